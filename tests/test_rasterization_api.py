"""splatting.raster.api.rasterization: several cameras in one call, extra feature channels, shapes."""
import torch

from splatting.gaussians.container import Gaussians
from splatting.gaussians.sh import rgb_to_sh0
from splatting.raster.api import rasterization, render_cameras, viewmat
from splatting.raster.camera import ring_camera
from splatting.raster.reference import render_reference
from splatting.raster.sparse import render_gaussians


def scene(n=60, seed=0, sh_degree=1):
    g = torch.Generator().manual_seed(seed)
    k = (sh_degree + 1) ** 2
    return Gaussians(means=torch.randn(n, 3, generator=g) * 0.3, quats=torch.randn(n, 4, generator=g),
                     log_scales=torch.randn(n, 3, generator=g) * 0.3 - 3.0,
                     opacity_logits=torch.randn(n, generator=g) + 1.0, sh=torch.randn(n, k, 3, generator=g) * 0.5)


def cams(size=40):
    return [ring_camera(a, size=size, focal=2084.97 * size / 512 * 0.25) for a in (0.0, 70.0, 200.0)]


def test_several_cameras_equal_one_call_each():
    g, cs = scene(), cams()
    colors, alphas, meta = render_cameras(g, cs)
    assert colors.shape == (3, 40, 40, 3) and alphas.shape == (3, 40, 40, 1) and meta["depths"].shape == (3, 40, 40)
    for i, c in enumerate(cs):
        one = render_gaussians(g, c)
        assert torch.allclose(colors[i], one["rgb"], atol=1e-6)
        assert torch.allclose(alphas[i, ..., 0], one["alpha"], atol=1e-6)
        assert alphas[i].max() > 0.5  # the scene is in view, so the comparison means something


def test_matches_reference_renderer():
    g, cs = scene(sh_degree=2), cams(24)
    colors, alphas, _ = render_cameras(g, cs)
    for i, c in enumerate(cs):
        ref = render_reference(g.means, g.quats, g.scales, g.opacities, g.sh, c)
        assert torch.allclose(colors[i].double(), ref["rgb"], atol=1e-5)
        assert torch.allclose(alphas[i, ..., 0].double(), ref["alpha"], atol=1e-5)


def test_plain_rgb_colours_equal_their_sh0():
    g, cs = scene(sh_degree=0), cams(24)
    rgb = torch.rand(len(g), 3, generator=torch.Generator().manual_seed(1))
    vm = torch.stack([viewmat(c) for c in cs])
    Ks = torch.stack([c.K for c in cs])
    a, _, _ = rasterization(g.means, g.quats, g.scales, g.opacities, rgb, vm, Ks, 24, 24)
    b, _, _ = rasterization(g.means, g.quats, g.scales, g.opacities, rgb_to_sh0(rgb)[:, None, :], vm, Ks, 24, 24,
                            sh_degree=0)
    assert torch.allclose(a, b, atol=1e-6)


def test_feature_channels_use_the_colour_weights():
    """A constant-1 feature composites to alpha; a one-hot split of the Gaussians sums to alpha and
    each channel is the render of its own subset's weights."""
    g, cs = scene(), cams(32)
    n = len(g)
    onehot = torch.zeros(n, 2)
    onehot[: n // 2, 0] = 1.0
    onehot[n // 2:, 1] = 1.0
    feats = torch.cat([torch.ones(n, 1), onehot], 1)
    colors, alphas, _ = render_cameras(g, cs, features=feats)
    assert colors.shape == (3, 32, 32, 6)
    assert torch.allclose(colors[..., 3], alphas[..., 0], atol=1e-5)
    assert torch.allclose(colors[..., 4] + colors[..., 5], alphas[..., 0], atol=1e-5)
    plain, _, _ = render_cameras(g, cs)
    assert torch.allclose(colors[..., :3], plain, atol=1e-6)  # features do not disturb the colour


def test_gradients_reach_every_input_through_features():
    g, cs = scene(n=30), cams(24)
    means = g.means.clone().requires_grad_(True)
    feats = torch.rand(len(g), 2, requires_grad=True)
    vm = torch.stack([viewmat(c) for c in cs])
    Ks = torch.stack([c.K for c in cs])
    colors, alphas, meta = rasterization(means, g.quats, g.scales, g.opacities, g.sh, vm, Ks, 24, 24,
                                         sh_degree=1, features=feats)
    (colors.sum() + alphas.sum()).backward()
    assert means.grad.abs().sum() > 0 and feats.grad.abs().sum() > 0
    assert all(m.grad is not None for m in meta["means2d"])

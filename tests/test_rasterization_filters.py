"""rasterization() takes the mip filter and the low-pass as arguments, as rasterize does: a
bool or a per-Gaussian mask for antialiased, a number or one value per Gaussian for eps2d; each
camera's image is rasterize()'s for that camera bit for bit."""
import torch

from splatting.gaussians.container import Gaussians
from splatting.raster.api import render_cameras
from splatting.raster.camera import ring_camera
from splatting.raster.sparse import render_gaussians


def scene(n=400, seed=1):
    g = torch.Generator().manual_seed(seed)
    # small Gaussians (a few tenths of a pixel at 48 px): where the mip filter changes the image
    return Gaussians(means=torch.randn(n, 3, generator=g) * 0.3, quats=torch.randn(n, 4, generator=g),
                     log_scales=torch.randn(n, 3, generator=g) * 0.3 - 5.5,
                     opacity_logits=torch.randn(n, generator=g) + 2.0, sh=torch.randn(n, 4, 3, generator=g) * 0.5)


def cams(size=48):
    return [ring_camera(a, size=size, focal=2084.97 * size / 512 * 0.25) for a in (0.0, 120.0)]


def test_antialiased_and_per_gaussian_eps2d_are_rasterize_bit_for_bit():
    g, cs = scene(), cams()
    mask = torch.arange(len(g)) % 2 == 0
    eps = torch.where(mask, torch.tensor(0.173, dtype=torch.float64), torch.tensor(0.3, dtype=torch.float64))
    for aa, e in ((True, 0.3), (mask, eps), (False, eps)):
        colors, alphas, _ = render_cameras(g, cs, antialiased=aa, eps2d=e)
        for i, c in enumerate(cs):
            one = render_gaussians(g, c, antialiased=aa, eps2d=e)
            assert torch.equal(colors[i], one["rgb"]) and torch.equal(alphas[i, ..., 0], one["alpha"])
    plain, _, _ = render_cameras(g, cs)
    filtered, _, _ = render_cameras(g, cs, antialiased=True)
    assert (plain - filtered).abs().max() > 1e-3  # the filter reaches the images: the comparison means something

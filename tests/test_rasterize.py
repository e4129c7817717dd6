"""Both rasterizer back ends ("tiles": the C++ one, "torch") against the reference renderer,
finite differences, and frame conventions. tests/test_rasterize_tiles.py compares the two back
ends with each other."""
import math

import pytest
import torch

from splatting.raster.camera import ring_camera
from splatting.gaussians.container import Gaussians
from splatting.raster.sparse import rasterize, render_gaussians
from splatting.raster.reference import render_reference

from helpers import dense_opaque_scene, look_at_camera, random_camera, random_scene, single_gaussian  # noqa: F401


@pytest.fixture(params=["tiles", "torch"])
def backend(request):
    return request.param


def assert_matches_reference(scene, cam, background=None, tol=1e-5, backend=None):
    out = rasterize(*scene, cam, background=background, backend=backend)
    assert out["backend"] == (backend or "tiles")
    ref = render_reference(*scene, cam, background=background)
    for key in ("rgb", "alpha", "depth"):
        err = (out[key].double() - ref[key]).abs().max().item()
        assert err <= tol, f"{key}: max abs error {err}"
    return out, ref


@pytest.mark.parametrize("sh_degree", [0, 1, 2, 3])
def test_matches_reference_random_scenes(sh_degree, backend):
    gen = torch.Generator().manual_seed(100 + sh_degree)
    for trial in range(3):
        scene = random_scene(gen, 40, sh_degree)
        cam = random_camera(gen)
        bg = torch.rand(3, generator=gen, dtype=torch.float64) if trial != 1 else None
        out, ref = assert_matches_reference(scene, cam, bg, backend=backend)
        assert ref["alpha"].max() > 0.3  # the scene is really on screen


def test_matches_reference_behind_huge_tiny(backend):
    gen = torch.Generator().manual_seed(7)
    means, quats, scales, opac, sh = random_scene(gen, 30, 2)
    cam = look_at_camera((0.0, 0.0, -3.0))
    # behind the camera and straddling the near plane
    means[:4] = torch.tensor([[0.0, 0.0, -4.0], [0.3, 0.2, -3.5], [0.0, 0.0, -3.005], [0.1, -0.1, -2.995]])
    scales[:4] = 0.5
    scales[4:8] = 4.0  # huge: cover the whole image
    opac[4:8] = 0.05
    scales[8:12] = 1e-4  # tiny: smaller than a pixel, the 0.3 px^2 low-pass dominates
    # far off to the side: x/z beyond the 1.3x FOV clamp of the Jacobian
    means[12] = torch.tensor([3.0, 0.1, 0.5])
    scales[12] = torch.tensor([2.0, 0.3, 0.3])
    out, ref = assert_matches_reference((means, quats, scales, opac, sh), cam,
                                        background=torch.tensor([0.2, 0.5, 0.9], dtype=torch.float64),
                                        backend=backend)
    assert not out["visible"][:2].any() and (out["radii"][:2] == 0).all()
    assert out["visible"][8:12].all()


def test_matches_reference_transmittance_cutoff(backend):
    """Many opaque Gaussians stacked on the view axis: compositing must stop at T < 1e-4."""
    gen = torch.Generator().manual_seed(3)
    n = 12
    means = torch.zeros(n, 3, dtype=torch.float64)
    means[:, 2] = torch.linspace(-0.5, 0.5, n, dtype=torch.float64)
    means[:, :2] = torch.randn(n, 2, generator=gen, dtype=torch.float64) * 0.05
    quats = torch.randn(n, 4, generator=gen, dtype=torch.float64)
    scales = torch.full((n, 3), 0.3, dtype=torch.float64)
    opac = torch.full((n,), 0.95, dtype=torch.float64)
    opac[1::3] = 0.999  # clamped to 0.99
    sh = torch.randn(n, 4, 3, generator=gen, dtype=torch.float64)
    cam = look_at_camera((0.0, 0.0, -3.0))
    out, ref = assert_matches_reference((means, quats, scales, opac, sh), cam,
                                        background=torch.tensor([1.0, 1.0, 1.0], dtype=torch.float64),
                                        backend=backend)
    # at the centre the front Gaussians bring T below 1e-4: the back half is never reached, so
    # recolouring it changes nothing there; the final T stays in [1e-4, 1e-4 / (1 - 0.99)]
    assert 1 - 1e-2 < out["alpha"][10, 12] <= 1 - 1e-4
    base = rasterize(means, quats, scales, opac, sh, cam, backend=backend)["rgb"][10, 12]
    sh2 = sh.clone()
    sh2[6:] += 1.0
    assert torch.equal(rasterize(means, quats, scales, opac, sh2, cam, backend=backend)["rgb"][10, 12], base)
    sh2[0] += 1.0  # the front one does count
    assert not torch.allclose(rasterize(means, quats, scales, opac, sh2, cam, backend=backend)["rgb"][10, 12], base)


def test_matches_reference_float32(backend):
    gen = torch.Generator().manual_seed(11)
    scene = random_scene(gen, 40, 3)
    cam = random_camera(gen)
    scene32 = [t.float() for t in scene]
    out = rasterize(*scene32, cam.to(torch.float32), backend=backend)
    ref = render_reference(*scene32, cam)
    assert out["rgb"].dtype == torch.float32
    assert (out["rgb"].double() - ref["rgb"]).abs().max() < 2e-4  # float32 rounding only


# ---------------------------------------------------------------- gradients

def _tiny_scene(seed, n=6, sh_degree=2):
    gen = torch.Generator().manual_seed(seed)
    means, quats, scales, opac, sh = random_scene(gen, n, sh_degree, spread=0.5)
    scales = scales.clamp_min(0.05)  # a few pixels wide: smooth enough for central differences
    opac = opac * 0.9
    cam = look_at_camera((0.4, -0.3, -3.0), width=14, height=12, focal=16.0)
    return (means, quats, scales, opac, sh), cam


@pytest.mark.parametrize("seed", [0, 1])
def test_gradcheck_all_parameters(seed, backend):
    scene, cam = _tiny_scene(seed)
    bg = torch.tensor([0.3, 0.1, 0.6], dtype=torch.float64)
    inputs = [t.clone().requires_grad_(True) for t in (*scene, bg)]
    wimg = torch.rand(cam.height, cam.width, 5, generator=torch.Generator().manual_seed(9), dtype=torch.float64)

    def f(means, quats, scales, opac, sh, bg):
        out = rasterize(means, quats, scales, opac, sh, cam, background=bg, backend=backend)
        img = torch.cat([out["rgb"], out["alpha"][..., None], out["depth"][..., None]], -1)
        return (img * wimg).sum()

    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)


def test_gradients_nonzero_and_means2d_retained(backend):
    scene, cam = _tiny_scene(4)
    scene = [t.clone().requires_grad_(True) for t in scene]
    out = rasterize(*scene, cam, backend=backend)
    out["rgb"].sum().backward()
    for name, t in zip(("means", "quats", "scales", "opacities", "sh"), scene):
        assert torch.isfinite(t.grad).all() and t.grad.abs().sum() > 0, name
    g2d = out["means2d"].grad
    assert g2d is not None and g2d.shape == (6, 2)
    assert (g2d[out["visible"]].abs().sum(-1) > 0).all()


# ---------------------------------------------------------------- conventions

def test_small_gaussian_lands_where_K_predicts():
    cam = look_at_camera((0.5, -0.2, -3.0), width=31, height=23, focal=25.0, cx=14.3, cy=12.9)
    X = torch.tensor([0.21, 0.13, 0.37], dtype=torch.float64)
    xc = cam.R @ X + cam.T
    u_px, v_px = (cam.K @ (xc / xc[2]))[:2].tolist()
    out = rasterize(*single_gaussian(X.tolist()), cam)
    a = out["alpha"]
    v, u = divmod(int(a.argmax()), cam.width)
    # the brightest pixel is the one whose centre (u + 0.5, v + 0.5) is nearest to K x / z
    assert (u, v) == (math.floor(u_px), math.floor(v_px)), ((u, v), (u_px, v_px))
    assert torch.allclose(out["means2d"][0], torch.tensor([u_px, v_px], dtype=torch.float64))
    # and the alpha there matches exp(-0.5 d^2 / 0.3) for the pure low-pass footprint
    d2 = (u + 0.5 - u_px) ** 2 + (v + 0.5 - v_px) ** 2
    assert abs(a[v, u].item() - 0.99 * math.exp(-0.5 * d2 / (0.3 + (25.0 * 1e-3 / xc[2].item()) ** 2))) < 1e-3


def test_ring_view0_plus_x_left_plus_y_up():
    cam = ring_camera(0, size=64, focal=200.0, dtype=torch.float64)
    c = cam.width / 2
    out_x = rasterize(*single_gaussian([0.5, 0.0, 0.0], scale=0.02), cam)
    out_y = rasterize(*single_gaussian([0.0, 0.5, 0.0], scale=0.02), cam)
    vx, ux = divmod(int(out_x["alpha"].argmax()), cam.width)
    vy, uy = divmod(int(out_y["alpha"].argmax()), cam.width)
    assert ux < c - 5 and abs(vx + 0.5 - c) <= 1  # +X world on the image's left
    assert vy < c - 5 and abs(uy + 0.5 - c) <= 1  # +Y world up (smaller row index)


def test_depth_is_camera_z_for_opaque_gaussian(backend):
    cam = look_at_camera((0.3, 0.2, -4.0))
    X = torch.tensor([0.05, -0.02, 0.1], dtype=torch.float64)
    z = (cam.R @ X + cam.T)[2].item()
    # many opaque copies at the same place: T reaches ~0, so sum w_i z_i = z
    scene = [t.repeat(10, *([1] * (t.dim() - 1))) for t in single_gaussian(X.tolist(), scale=0.3, opacity=1.0)]
    out = rasterize(*scene, cam, backend=backend)
    v, u = divmod(int(out["alpha"].argmax()), cam.width)
    assert out["alpha"][v, u] > 0.999
    assert abs(out["depth"][v, u].item() - z) < 1e-3 * z
    assert abs((out["depth"][v, u] / out["alpha"][v, u]).item() - z) < 1e-9


def test_empty_and_all_culled(backend):
    cam = look_at_camera((0.0, 0.0, -3.0))
    bg = torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)
    empty = (torch.zeros(0, 3, dtype=torch.float64), torch.zeros(0, 4, dtype=torch.float64),
             torch.zeros(0, 3, dtype=torch.float64), torch.zeros(0, dtype=torch.float64),
             torch.zeros(0, 1, 3, dtype=torch.float64))
    behind = single_gaussian([0.0, 0.0, -5.0], scale=0.5)
    for scene in (empty, behind):
        scene = [t.clone().requires_grad_(True) for t in scene]
        out = rasterize(*scene, cam, background=bg, backend=backend)
        assert out["rgb"].shape == (20, 24, 3) and out["alpha"].shape == (20, 24)
        assert torch.equal(out["rgb"], bg.expand(20, 24, 3))
        assert (out["alpha"] == 0).all() and (out["depth"] == 0).all()
        assert not out["visible"].any()
        out["rgb"].sum().backward()  # no error, zero gradients
        assert all(t.grad is None or (t.grad == 0).all() for t in scene)


def test_render_gaussians_applies_activations():
    gen = torch.Generator().manual_seed(5)
    means, quats, scales, opac, sh = random_scene(gen, 20, 1)
    g = Gaussians(means, quats, torch.log(scales), torch.logit(opac), sh)
    cam = random_camera(gen)
    a = render_gaussians(g, cam)["rgb"]
    b = rasterize(means, quats, scales, opac, sh, cam)["rgb"]
    assert torch.allclose(a, b, atol=1e-10)


# ---------------------------------------------------------------- front-to-back chunks

@pytest.fixture
def tiny_chunks(monkeypatch):
    """Force intersect() through many front-to-back chunks (the early cut-off path)."""
    import splatting.raster.torch_composite as R

    monkeypatch.setattr(R, "CHUNK_PAIRS", 64)


def test_chunked_matches_reference(tiny_chunks):
    scene = dense_opaque_scene(21)
    cam = look_at_camera((0.2, 0.1, -3.0))
    out, ref = assert_matches_reference(scene, cam, background=torch.tensor([0.4, 0.4, 0.1], dtype=torch.float64),
                                        backend="torch")
    assert (ref["alpha"] > 1 - 1e-2).sum() > 20  # many pixels reach the cut-off


def test_chunked_gradcheck(tiny_chunks):
    gen = torch.Generator().manual_seed(22)
    means, quats, scales, opac, sh = random_scene(gen, 8, 1, spread=0.1)
    scene = [t.clone().requires_grad_(True) for t in (means, quats, scales.clamp_min(0.08), 0.3 + 0.6 * opac, sh)]
    cam = look_at_camera((0.0, 0.0, -3.0), width=10, height=9, focal=12.0)
    f = lambda *p: rasterize(*p, cam, backend="torch")["rgb"].sum() + 0.3 * rasterize(*p, cam, backend="torch")["depth"].sum()
    assert torch.autograd.gradcheck(f, scene, eps=1e-6, atol=1e-6, rtol=1e-4)


def test_chunks_drop_pairs_behind_the_cutoff(monkeypatch):
    import splatting.raster.sparse as R

    means, quats, scales, opac, sh = dense_opaque_scene(21)
    cam = look_at_camera((0.2, 0.1, -3.0))
    m2, cn, z, radii, boxes = R.project(means, quats, scales, cam)
    n_all = len(R.intersect(m2, cn, opac, z, boxes, radii, cam.width, cam.height, chunk_pairs=1 << 30)[0])
    n_cut = len(R.intersect(m2, cn, opac, z, boxes, radii, cam.width, cam.height, chunk_pairs=64)[0])
    assert n_cut < 0.95 * n_all


# ---------------------------------------------------------------- anti-aliasing

def test_antialiased_matches_reference(backend):
    gen = torch.Generator().manual_seed(61)
    means, quats, scales, opac, sh = random_scene(gen, 40, 2)
    scales[:10] = 2e-3  # sub-pixel: the compensation matters
    cam = random_camera(gen)
    bg = torch.tensor([0.5, 0.2, 0.1], dtype=torch.float64)
    out = rasterize(means, quats, scales, opac, sh, cam, background=bg, antialiased=True, backend=backend)
    ref = render_reference(means, quats, scales, opac, sh, cam, background=bg, antialiased=True)
    plain = render_reference(means, quats, scales, opac, sh, cam, background=bg)
    for key in ("rgb", "alpha", "depth"):
        assert (out[key] - ref[key]).abs().max() <= 1e-5, key
    assert (ref["alpha"] - plain["alpha"]).abs().max() > 0.05  # the option does something


def test_antialiased_gradcheck(backend):
    scene, cam = _tiny_scene(8)
    inputs = [t.clone().requires_grad_(True) for t in scene]
    f = lambda *p: (rasterize(*p, cam, antialiased=True, backend=backend)["rgb"] ** 2).sum()
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)


def test_antialiased_keeps_a_subpixel_footprint(backend):
    """A sub-pixel Gaussian (0.3 px std): with the compensation the image's total alpha is the
    integral of its true footprint, o 2 pi sqrt(det S), less the tail under the 1/255 cut
    (a fraction 1 / (255 o') of it, o' the compensated peak); the 0.3 px^2 dilation alone
    inflates it ~4x."""
    cam = look_at_camera((0.0, 0.0, -3.0), width=32, height=32, focal=30.0, cx=16.3, cy=15.8)
    scene = single_gaussian([0.0, 0.0, 0.0], scale=0.03, opacity=0.5)
    sx, sy = 30.0 * 0.03 / 3.0, 33.0 * 0.03 / 3.0  # fx s / z, fy s / z (look_at_camera: fy = 1.1 fx)
    det_s = sx * sx * sy * sy
    o_aa = 0.5 * math.sqrt(det_s / ((sx * sx + 0.3) * (sy * sy + 0.3)))
    expected = 0.5 * 2 * math.pi * math.sqrt(det_s) * (1 - 1 / (255 * o_aa))
    aa = rasterize(*scene, cam, antialiased=True, backend=backend)["alpha"].sum().item()
    plain = rasterize(*scene, cam, backend=backend)["alpha"].sum().item()
    assert abs(aa - expected) < 0.01 * expected, (aa, expected)
    assert plain > 3 * expected

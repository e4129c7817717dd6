"""rasterize(eps2d=) per Gaussian: a (N,) tensor of screen-space low-pass variances, for scenes that
compose models trained with different filters (a bike at Cycles' 0.173 px^2 beside a rider at 0.3).
Both back ends against the float64 reference (which adds each Gaussian's own eps2d to its 2D
covariance, written from the formula), the C++ gradients against the torch back end's and finite
differences, a number and a constant tensor bit for bit, and the refusals."""
import pytest
import torch

from splatting.raster.cpu_project import preprocess
from splatting.raster.reference import render_reference
from splatting.raster.sparse import rasterize

from helpers import look_at_camera, random_camera, random_scene

F64 = torch.float64


@pytest.fixture(params=["tiles", "torch"])
def backend(request):
    return request.param


def _mixed(n):
    """Half the Gaussians at 0.3 (the rider's filter), half at 0.173 (Cycles'), interleaved."""
    e = torch.full((n,), 0.3, dtype=F64)
    e[1::2] = 0.173
    return e


def _scene(seed, n=40):
    gen = torch.Generator().manual_seed(seed)
    means, quats, scales, opac, sh = random_scene(gen, n, 2)
    scales[: n // 3] = 3e-3  # sub-pixel: the low-pass decides their footprint and, antialiased, their opacity
    return (means, quats, scales, opac, sh), random_camera(gen)


@pytest.mark.parametrize("antialiased", [False, True])
def test_mixed_eps2d_matches_the_reference(backend, antialiased):
    scene, cam = _scene(71)
    bg = torch.tensor([0.2, 0.6, 0.3], dtype=F64)
    eps = _mixed(len(scene[0]))
    out = rasterize(*scene, cam, background=bg, eps2d=eps, antialiased=antialiased, backend=backend)
    ref = render_reference(*scene, cam, background=bg, eps2d=eps, antialiased=antialiased)
    for key in ("rgb", "alpha", "depth"):
        err = (out[key] - ref[key]).abs().max().item()
        assert err <= 1e-5, f"{key}: max abs error {err}"
    # the per-Gaussian values are what was drawn: either uniform value gives another image
    for uniform in (0.3, 0.173):
        other = render_reference(*scene, cam, background=bg, eps2d=uniform, antialiased=antialiased)
        assert (other["alpha"] - ref["alpha"]).abs().max() > 1e-3, uniform


@pytest.mark.parametrize("antialiased", [False, True])
def test_mixed_eps2d_gradients_tiles_equal_torch(antialiased):
    scene, cam = _scene(72, 50)
    eps = _mixed(len(scene[0]))
    res = {}
    for backend in ("tiles", "torch"):
        ps = [t.clone().requires_grad_(True) for t in scene]
        out = rasterize(*ps, cam, eps2d=eps, antialiased=antialiased, backend=backend)
        w = torch.rand(out["rgb"].shape[:2] + (5,), generator=torch.Generator().manual_seed(3), dtype=F64)
        img = torch.cat([out["rgb"], out["alpha"][..., None], out["depth"][..., None]], -1)
        (img * w).sum().backward()
        res[backend] = [p.grad for p in ps] + [out["means2d"].grad]
    for name, a, b in zip(("means", "quats", "scales", "opacities", "sh", "means2d"), res["tiles"], res["torch"]):
        scale = max(1.0, b.abs().max().item())
        assert (a - b).abs().max().item() <= 1e-5 * scale, name
        assert b.abs().sum() > 0, name  # something was differentiated


@pytest.mark.parametrize("antialiased", [False, True])
def test_mixed_eps2d_gradcheck(backend, antialiased):
    gen = torch.Generator().manual_seed(5)
    means, quats, scales, opac, sh = random_scene(gen, 6, 1, spread=0.5)
    scales = scales.clamp_min(0.05)  # a few pixels wide: smooth enough for central differences
    cam = look_at_camera((0.4, -0.3, -3.0), width=14, height=12, focal=16.0)
    eps = _mixed(6) * torch.linspace(1.0, 3.0, 6, dtype=F64)  # six different values
    inputs = [t.clone().requires_grad_(True) for t in (means, quats, scales, opac * 0.9, sh)]

    def f(*p):
        out = rasterize(*p, cam, eps2d=eps, antialiased=antialiased, backend=backend)
        return (out["rgb"] ** 2).sum() + out["alpha"].sum()

    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)


@pytest.mark.parametrize("dtype", [torch.float32, F64])
@pytest.mark.parametrize("antialiased", [False, True])
def test_a_number_and_a_constant_tensor_are_bit_identical(backend, dtype, antialiased):
    scene, cam = _scene(73)
    scene = [t.to(dtype) for t in scene]
    res = []
    for eps in (0.173, torch.full((len(scene[0]),), 0.173, dtype=dtype)):
        ps = [t.clone().requires_grad_(True) for t in scene]
        out = rasterize(*ps, cam, eps2d=eps, antialiased=antialiased, backend=backend)
        (out["rgb"].sum() + out["alpha"].square().sum() + out["depth"].sum()).backward()
        res.append([out[k].detach() for k in ("rgb", "alpha", "depth", "radii")] + [p.grad for p in ps])
    for a, b in zip(*res):
        assert torch.equal(a, b)


def test_a_float64_tensor_with_float32_gaussians_is_rounded_like_the_number(backend):
    """The per-Gaussian values are cast to the Gaussians' dtype, as a number is."""
    scene, cam = _scene(74)
    scene = [t.float() for t in scene]
    a = rasterize(*scene, cam, eps2d=0.173, backend=backend)
    b = rasterize(*scene, cam, eps2d=torch.full((len(scene[0]),), 0.173, dtype=F64), backend=backend)
    assert torch.equal(a["rgb"], b["rgb"]) and torch.equal(a["alpha"], b["alpha"])


@pytest.mark.parametrize("bad,match", [
    (torch.full((39,), 0.3, dtype=F64), r"eps2d must be a number or a \(40,\) floating tensor"),
    (torch.full((40, 1), 0.3, dtype=F64), r"\(40, 1\)"),
    (torch.full((40,), 1, dtype=torch.int64), r"floating tensor"),
    (torch.tensor([0.3] * 39 + [float("nan")], dtype=F64), r"finite and >= 0 for every Gaussian, got nan"),
    (torch.tensor([0.3] * 39 + [-0.1], dtype=F64), r"finite and >= 0 for every Gaussian, got -0.1"),
    (torch.tensor([float("inf")] * 40, dtype=F64), r"got inf"),
    (float("nan"), r"eps2d must be finite and >= 0, got nan"),
    (-0.3, r"eps2d must be finite and >= 0, got -0.3"),
    ("0.3", r"eps2d must be a number"),
    (True, r"eps2d must be a number"),
])
def test_bad_eps2d_is_refused(backend, bad, match):
    scene, cam = _scene(75)
    with pytest.raises(ValueError, match=match):
        rasterize(*scene, cam, eps2d=bad, backend=backend)


def test_preprocess_refuses_bad_eps2d_too():
    scene, cam = _scene(76)
    means, quats, scales, _, sh = scene
    with pytest.raises(ValueError, match=r"preprocess: eps2d must be a number or a \(40,\)"):
        preprocess(means, quats, scales, sh, cam, eps2d=torch.zeros(3, dtype=F64))

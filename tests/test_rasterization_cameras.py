"""Several cameras in one rasterization() call: one pass of the C++ back end (csrc/tiles.cpp
forward_cameras), each camera's image bit-identical to its render alone."""
import pytest
import torch

from splatting.raster.api import rasterization, rasterize
from splatting.raster.camera import ring_camera


def scene(n=3000, dtype=torch.float32, seed=0):
    g = torch.Generator().manual_seed(seed)
    means = (torch.randn(n, 3, generator=g) * torch.tensor([0.5, 0.3, 0.1])).to(dtype)
    quats = torch.randn(n, 4, generator=g).to(dtype)
    scales = torch.exp(torch.rand(n, 3, generator=g) * 3.0 - 6.5).to(dtype)
    opac = (0.1 + 0.9 * torch.rand(n, generator=g)).to(dtype)
    sh = (torch.randn(n, 16, 3, generator=g) * 0.3).to(dtype)
    return means, quats, scales, opac, sh


def cams(size=96):
    # four views, two of them off the ring's size so cx != W/2 does not hide an offset bug
    return [ring_camera(a, size=size, focal=2085 * size / 512, distance=4.0) for a in (0.0, 40.0, 130.0, 275.0)]


CASES = {
    "plain": {},
    "features": {"features": "f"},
    "feature parts": {"features": "parts"},
    "eps2d per Gaussian, masked mip filter": {"eps2d": "per", "antialiased": "mask"},
    "mip filter, one background": {"antialiased": True, "backgrounds": "one"},
    "a background per camera, no depth": {"backgrounds": "each", "depth": False},
    "sh degree 0": {"sh_degree": 0},
    "sh degree 1": {"sh_degree": 1},
    "sh degree 2": {"sh_degree": 2},
}


def _kw(spec, n, dtype):
    g = torch.Generator().manual_seed(5)
    feats = torch.rand(n, 3, generator=g).to(dtype)
    kw = dict(spec)
    if spec.get("features") == "f":
        kw["features"] = feats
    if spec.get("features") == "parts":
        kw["features"] = [feats[:, :1], feats[:, 1:]]
    if spec.get("eps2d") == "per":
        kw["eps2d"] = torch.where(torch.arange(n) % 2 == 0, 0.3, 0.173).double()
    if spec.get("antialiased") == "mask":
        kw["antialiased"] = torch.arange(n) % 3 == 0
    if spec.get("backgrounds") == "one":
        kw["backgrounds"] = torch.tensor([0.2, 0.4, 0.6], dtype=dtype)
    if spec.get("backgrounds") == "each":
        kw["backgrounds"] = torch.rand(4, 3, generator=g).to(dtype)
    return kw


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("case", list(CASES))
def test_one_pass_equals_each_camera_alone_bit_for_bit(case, dtype):
    means, quats, scales, opac, sh = scene(dtype=dtype)
    cs = cams()
    kw = _kw(CASES[case], len(means), dtype)
    with torch.no_grad():
        outs = rasterization(means, quats, scales, opac, sh, cameras=cs, per_camera=True, **kw)
        colors, alphas, meta = rasterization(means, quats, scales, opac, sh, cameras=cs, **kw)
    assert meta["batched"] and meta["backend"] == "tiles"
    bgs = kw.pop("backgrounds", None)
    for i, c in enumerate(cs):
        bg = None if bgs is None else bgs if bgs.dim() == 1 else bgs[i]
        with torch.no_grad():
            one = rasterize(means, quats, scales, opac, sh, c, bg, **kw)
        assert one["alpha"].max() > 0.5  # the scene is in view of every camera
        assert set(one) == set(outs[i])
        for k, v in one.items():
            if torch.is_tensor(v):
                assert torch.equal(v, outs[i][k]), (case, i, k)
        assert torch.equal(alphas[i, ..., 0], one["alpha"])
        assert torch.equal(colors[i, ..., :3], one["rgb"])
        if "features" in one:
            assert torch.equal(colors[i, ..., 3:], one["features"])
        if "depth" in one:
            assert torch.equal(meta["depths"][i], one["depth"])


def test_one_pass_is_the_same_for_any_thread_count():
    means, quats, scales, opac, sh = scene()
    prev = torch.get_num_threads()
    try:
        res = []
        for nt in (1, 2, 3):
            torch.set_num_threads(nt)
            with torch.no_grad():
                res.append(rasterization(means, quats, scales, opac, sh, cameras=cams()))
    finally:
        torch.set_num_threads(prev)
    for c, a, m in res[1:]:
        assert torch.equal(c, res[0][0]) and torch.equal(a, res[0][1]) and torch.equal(m["depths"], res[0][2]["depths"])


def test_a_camera_with_nothing_in_view_is_empty_beside_the_others():
    means, quats, scales, opac, sh = scene()
    away = ring_camera(0.0, size=96, focal=2085 * 96 / 512, distance=4.0)
    away.T = away.T - torch.tensor([0.0, 0.0, 20.0])  # moved 20 m forward, past the scene: all of it behind
    with torch.no_grad():
        colors, alphas, meta = rasterization(means, quats, scales, opac, sh, cameras=[cams()[0], away])
    assert meta["batched"]
    assert alphas[0].max() > 0.5 and alphas[1].abs().max() == 0 and colors[1].abs().max() == 0
    assert (meta["radii"][1] == 0).all() and (meta["radii"][0] > 0).any()


def test_with_a_gradient_the_cameras_are_rendered_one_by_one_and_both_get_gradients():
    means, quats, scales, opac, sh = scene(n=500)
    means = means.clone().requires_grad_(True)
    colors, alphas, meta = rasterization(means, quats, scales, opac, sh, cameras=cams()[:2])
    assert not meta["batched"]
    colors[0].sum().backward(retain_graph=True)
    g0 = means.grad.clone()
    means.grad = None
    colors[1].sum().backward()
    assert g0.abs().sum() > 0 and means.grad.abs().sum() > 0 and not torch.equal(g0, means.grad)


def test_bad_camera_arguments_are_one_clear_error():
    means, quats, scales, opac, sh = scene(n=50)
    small = ring_camera(0.0, size=48)
    with pytest.raises(ValueError, match="one size"):
        rasterization(means, quats, scales, opac, sh, cameras=[cams()[0], small])
    with pytest.raises(ValueError, match="backgrounds"):
        rasterization(means, quats, scales, opac, sh, cameras=cams(), backgrounds=torch.zeros(3, 3))
    with pytest.raises(ValueError, match="not both"):
        rasterization(means, quats, scales, opac, sh)


def test_no_gaussians_gives_empty_images_over_the_backgrounds():
    means, quats, scales, opac, sh = (t[:0] for t in scene(n=10))
    bgs = torch.tensor([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    with torch.no_grad():
        colors, alphas, meta = rasterization(means, quats, scales, opac, sh, cameras=cams()[:2], backgrounds=bgs)
    assert meta["batched"] and colors.shape == (2, 96, 96, 3)
    assert alphas.abs().max() == 0 and meta["depths"].abs().max() == 0
    assert torch.equal(colors, bgs[:, None, None, :].expand(2, 96, 96, 3))


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_shared_covariance_factor_keeps_each_cameras_bits_for_any_quaternion(dtype):
    # the one pass computes each Gaussian's rotation and 3D covariance factor once for every camera
    # (blocks of 256): quaternions far from unit length, a zero one and a NaN scale (both culled),
    # and a count that leaves a partial last block must still give every camera its render alone
    means, quats, scales, opac, sh = scene(n=700, dtype=dtype)
    g = torch.Generator().manual_seed(3)
    quats = quats * torch.exp(torch.rand(700, 1, generator=g) * 14.0 - 7.0).to(dtype)
    quats[5] = 0.0
    scales[9, 1] = float("nan")
    cs = cams()
    with torch.no_grad():
        outs = rasterization(means, quats, scales, opac, sh, cameras=cs, per_camera=True)
        alone = [rasterize(means, quats, scales, opac, sh, c) for c in cs]
    for i, one in enumerate(alone):
        assert one["alpha"].max() > 0.5 and int(one["radii"][5]) == 0 and int(one["radii"][9]) == 0
        for k, v in one.items():
            if torch.is_tensor(v):
                torch.testing.assert_close(outs[i][k], v, rtol=0, atol=0, equal_nan=True, msg=f"camera {i}: {k}")


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_gradients_of_a_several_camera_call_equal_those_of_one_call_per_camera(dtype):
    # a loss over every camera's colour, alpha and depth: the same gradients, bit for bit, whether
    # the cameras come in one rasterization() call or one call each
    params = [p.clone().requires_grad_(True) for p in scene(n=800, dtype=dtype)]
    cs = cams()
    w = torch.rand(len(cs), 96, 96, 3, generator=torch.Generator().manual_seed(1), dtype=dtype)

    def loss(colors, alphas, depths, i):
        return (colors * w[i]).sum() + 0.3 * alphas.sum() + 0.01 * depths.sum()

    colors, alphas, meta = rasterization(*params, cameras=cs)
    sum(loss(colors[i], alphas[i], meta["depths"][i], i) for i in range(len(cs))).backward()
    together = [p.grad.clone() for p in params]
    for p in params:
        p.grad = None
    total = 0
    for i, c in enumerate(cs):
        colors, alphas, meta = rasterization(*params, cameras=[c])
        total = total + loss(colors[0], alphas[0], meta["depths"][0], i)
    total.backward()
    for name, a, p in zip(("means", "quats", "scales", "opacities", "sh"), together, params):
        assert a.abs().sum() > 0, name
        assert torch.equal(a, p.grad), name


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_more_cameras_than_colour_lanes_keep_each_cameras_bits(dtype):
    # the one pass shades up to 8 (float32) or 4 (float64) cameras per Gaussian at once: nine
    # cameras take two or three such groups, the last one partly filled
    means, quats, scales, opac, sh = scene(n=600, dtype=dtype)
    cs = [ring_camera(a, size=64, focal=2085 * 64 / 512, distance=4.0) for a in range(0, 360, 40)]
    with torch.no_grad():
        outs = rasterization(means, quats, scales, opac, sh, cameras=cs, per_camera=True)
        for i, c in enumerate(cs):
            one = rasterize(means, quats, scales, opac, sh, c)
            assert one["alpha"].max() > 0.5
            for k in ("rgb", "alpha", "depth", "means2d", "radii"):
                assert torch.equal(outs[i][k], one[k]), (i, k)

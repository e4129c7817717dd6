"""The tiled C++ back end against the torch back end: forward and every parameter's gradient to
1e-5 on each edge case of tests/test_rasterize.py, extra feature channels, 1 vs 2 threads, and the
back-end choice."""
import pytest
import torch

from splatting.raster.sparse import rasterize
from splatting.raster.reference import render_reference
from helpers import dense_opaque_scene, look_at_camera, random_camera, random_scene, single_gaussian

F64 = torch.float64


def _scenes():
    """(name, scene, camera, background) for each edge case the reference tests cover."""
    out = []
    for sh_degree in range(4):
        gen = torch.Generator().manual_seed(300 + sh_degree)
        bg = torch.rand(3, generator=gen, dtype=F64) if sh_degree % 2 == 0 else None
        out.append((f"random_sh{sh_degree}", random_scene(gen, 40, sh_degree), random_camera(gen), bg))
    gen = torch.Generator().manual_seed(7)
    means, quats, scales, opac, sh = random_scene(gen, 30, 2)
    means[:4] = torch.tensor([[0.0, 0.0, -4.0], [0.3, 0.2, -3.5], [0.0, 0.0, -3.005], [0.1, -0.1, -2.995]])
    scales[:4] = 0.5  # behind the camera / straddling the near plane
    scales[4:8], opac[4:8] = 4.0, 0.05  # huge
    scales[8:12] = 1e-4  # tiny
    means[12], scales[12] = torch.tensor([3.0, 0.1, 0.5]), torch.tensor([2.0, 0.3, 0.3])  # beyond the FOV clamp
    out.append(("behind_huge_tiny", (means, quats, scales, opac, sh), look_at_camera((0.0, 0.0, -3.0)),
                torch.tensor([0.2, 0.5, 0.9], dtype=F64)))
    n = 12
    gen = torch.Generator().manual_seed(3)
    means = torch.zeros(n, 3, dtype=F64)
    means[:, 2] = torch.linspace(-0.5, 0.5, n, dtype=F64)
    means[:, :2] = torch.randn(n, 2, generator=gen, dtype=F64) * 0.05
    opac = torch.full((n,), 0.95, dtype=F64)
    opac[1::3] = 0.999  # clamped to 0.99
    out.append(("cutoff_stack", (means, torch.randn(n, 4, generator=gen, dtype=F64), torch.full((n, 3), 0.3, dtype=F64),
                                 opac, torch.randn(n, 4, 3, generator=gen, dtype=F64)),
                look_at_camera((0.0, 0.0, -3.0)), torch.ones(3, dtype=F64)))
    out.append(("dense_opaque", dense_opaque_scene(21), look_at_camera((0.2, 0.1, -3.0)),
                torch.tensor([0.4, 0.4, 0.1], dtype=F64)))
    # equal depths: ten copies of one Gaussian (the tie order decides how gradients are shared)
    out.append(("equal_depths", [t.repeat(10, *([1] * (t.dim() - 1))) for t in single_gaussian([0.05, -0.02, 0.1], scale=0.3, opacity=0.7)],
                look_at_camera((0.3, 0.2, -4.0)), None))
    out.append(("behind_only", single_gaussian([0.0, 0.0, -5.0], scale=0.5), look_at_camera((0.0, 0.0, -3.0)),
                torch.tensor([0.1, 0.2, 0.3], dtype=F64)))
    out.append(("empty", (torch.zeros(0, 3, dtype=F64), torch.zeros(0, 4, dtype=F64), torch.zeros(0, 3, dtype=F64),
                          torch.zeros(0, dtype=F64), torch.zeros(0, 1, 3, dtype=F64)),
                look_at_camera((0.0, 0.0, -3.0)), torch.tensor([0.1, 0.2, 0.3], dtype=F64)))
    return out


SCENES = _scenes()


def _run(backend, scene, cam, bg, features=None, seed=0):
    """Forward outputs and the gradients of a random weighting of every output channel."""
    params = [t.clone().requires_grad_(True) for t in scene]
    bg = None if bg is None else bg.clone().requires_grad_(True)
    feats = None if features is None else features.clone().requires_grad_(True)
    out = rasterize(*params, cam, background=bg, features=feats, backend=backend)
    assert out["backend"] == backend
    chans = [out["rgb"], out["alpha"][..., None], out["depth"][..., None]]
    if feats is not None:
        chans.append(out["features"])
    img = torch.cat(chans, -1)
    w = torch.rand(img.shape, generator=torch.Generator().manual_seed(seed), dtype=img.dtype)
    (img * w).sum().backward()
    grads = [p.grad for p in params] + [None if bg is None else bg.grad, None if feats is None else feats.grad]
    return out, grads, out["means2d"].grad


def _assert_close(a, b, what, tol=1e-5):
    if a is None or b is None:
        assert (a is None or not a.abs().any()) and (b is None or not b.abs().any()), what
        return
    err = (a - b).abs().max().item() if a.numel() else 0.0
    scale = max(1.0, b.abs().max().item() if b.numel() else 0.0)
    assert err <= tol * scale, f"{what}: max abs error {err} (scale {scale})"


@pytest.mark.parametrize("name,scene,cam,bg", SCENES, ids=[s[0] for s in SCENES])
def test_tiles_match_torch_forward_and_gradients(name, scene, cam, bg):
    a, ga, m2a = _run("tiles", scene, cam, bg)
    b, gb, m2b = _run("torch", scene, cam, bg)
    for key in ("rgb", "alpha", "depth", "means2d"):
        _assert_close(a[key].detach(), b[key].detach(), f"{name} {key}")
    assert torch.equal(a["radii"], b["radii"])
    for pname, x, y in zip(("means", "quats", "scales", "opacities", "sh", "background", "features"), ga, gb):
        _assert_close(x, y, f"{name} d/d{pname}")
    _assert_close(m2a, m2b, f"{name} means2d.grad")
    if name.startswith("random"):
        assert a["alpha"].max() > 0.3 and ga[0].abs().sum() > 0  # something was drawn and differentiated


def test_features_ride_along_with_the_colour():
    """F extra channels: both back ends agree with each other and with the reference renderer;
    a constant-1 feature composites to alpha, a depth feature to the depth image."""
    gen = torch.Generator().manual_seed(41)
    scene = random_scene(gen, 50, 2)
    cam = random_camera(gen)
    means = scene[0]
    z = means @ cam.R[2] + cam.T[2]
    feats = torch.cat([torch.rand(50, 3, generator=gen, dtype=F64), torch.ones(50, 1, dtype=F64), z[:, None]], 1)
    bg = torch.tensor([0.3, 0.6, 0.9], dtype=F64)
    a, ga, _ = _run("tiles", scene, cam, bg, feats, seed=1)
    b, gb, _ = _run("torch", scene, cam, bg, feats, seed=1)
    ref = render_reference(*scene, cam, background=bg, features=feats)
    assert a["features"].shape == (cam.height, cam.width, 5)
    _assert_close(a["features"].detach(), ref["features"], "features vs reference")
    _assert_close(a["rgb"].detach(), ref["rgb"], "rgb vs reference")
    _assert_close(a["features"].detach(), b["features"].detach(), "features tiles vs torch")
    _assert_close(ga[-1], gb[-1], "d/dfeatures")
    _assert_close(ga[0], gb[0], "d/dmeans with features")
    _assert_close(a["features"][..., 3].detach(), a["alpha"].detach(), "constant feature = alpha", tol=1e-12)
    _assert_close(a["features"][..., 4].detach(), a["depth"].detach(), "depth feature = depth", tol=1e-12)
    assert ga[-1].abs().sum() > 0


@pytest.mark.parametrize("backend", ["tiles", "torch"])
def test_feature_parts_and_no_depth_equal_one_table(backend):
    """features as a list of parts composite as their concatenation (the tiled back end gathers
    them without building the table), each part gets its own columns' gradient; depth=False
    leaves the depth out and changes nothing else, bit for bit (3 + 4 channels: the compositor's
    compile-time 7-channel path against its any-count path for 3 + 4 + 1)."""
    gen = torch.Generator().manual_seed(43)
    scene = random_scene(gen, 60, 0)
    cam = random_camera(gen)
    table = torch.rand(60, 4, generator=gen, dtype=F64)
    w = torch.rand(cam.height, cam.width, 4, generator=gen, dtype=F64)
    outs, grads = [], []
    for parts, depth in ((None, True), ((3, 1), True), ((1, 3), False)):
        if parts is None:
            f = table.clone().requires_grad_(True)
            feats = f
        else:
            feats = [t.clone().requires_grad_(True) for t in table.split(parts, 1)]
        out = rasterize(*scene, cam, features=feats, backend=backend, depth=depth)
        assert ("depth" in out) == depth
        (out["features"] * w).sum().backward()
        outs.append(out)
        grads.append(f.grad if parts is None else torch.cat([t.grad for t in feats], 1))
    assert float(outs[0]["alpha"].detach().max()) > 0.3 and float(grads[0].abs().sum()) > 0
    for o, g in zip(outs[1:], grads[1:]):
        for k in ("rgb", "alpha", "features"):
            assert torch.equal(o[k], outs[0][k]), k
        assert torch.equal(g, grads[0])
    assert torch.equal(outs[1]["depth"], outs[0]["depth"])


def test_forward_only_renders_reusing_scratch_match_fresh_ones():
    """Without grad the compositor's scratch is a per-thread buffer kept across calls
    (cpu_tiles._buffer): renders of growing and shrinking sizes in a row equal renders that
    allocate afresh (with grad), bit for bit."""
    gen = torch.Generator().manual_seed(44)
    scenes = [(random_scene(gen, n, 1), random_camera(gen)) for n in (30, 200, 30)]
    feats = [torch.rand(len(sc[0]), 4, generator=gen, dtype=F64) for sc, _ in scenes]
    with torch.no_grad():
        kept = [rasterize(*sc, cam, features=f, backend="tiles") for (sc, cam), f in zip(scenes, feats)]
    for (sc, cam), f, k in zip(scenes, feats, kept):
        fresh = rasterize(*[t.clone().requires_grad_(True) for t in sc], cam, features=f, backend="tiles")
        assert float(fresh["alpha"].detach().max()) > 0.1
        for key in ("rgb", "alpha", "depth", "features"):
            assert torch.equal(k[key], fresh[key].detach()), key


def test_tiles_gradcheck_with_features():
    gen = torch.Generator().manual_seed(5)
    means, quats, scales, opac, sh = random_scene(gen, 7, 1, spread=0.5)
    scene = (means, quats, scales.clamp_min(0.05), opac * 0.9, sh)
    cam = look_at_camera((0.4, -0.3, -3.0), width=14, height=12, focal=16.0)
    feats = torch.rand(7, 2, generator=gen, dtype=F64)
    inputs = [t.clone().requires_grad_(True) for t in (*scene, feats)]
    wimg = torch.rand(cam.height, cam.width, 7, generator=torch.Generator().manual_seed(2), dtype=F64)

    def f(means, quats, scales, opac, sh, feats):
        out = rasterize(means, quats, scales, opac, sh, cam, features=feats, backend="tiles")
        img = torch.cat([out["rgb"], out["alpha"][..., None], out["depth"][..., None], out["features"]], -1)
        return (img * wimg).sum()

    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)


def test_threads_do_not_change_a_bit():
    """Tiles are blended independently and gradients summed per Gaussian in a fixed order."""
    from bench.raster import bike_like_gaussians
    from splatting.raster.camera import ring_camera

    params = bike_like_gaussians(3000, sh_degree=1)
    cam = ring_camera(30.0, size=128, focal=520.0)
    old = torch.get_num_threads()
    res = []
    try:
        for nt in (1, 2):
            torch.set_num_threads(nt)
            ps = [p.clone().requires_grad_(True) for p in params]
            out = rasterize(*ps, cam, backend="tiles")
            (out["rgb"].sum() + out["depth"].sum()).backward()
            res.append([out["rgb"], out["depth"]] + [p.grad for p in ps])
    finally:
        torch.set_num_threads(old)
    assert res[0][0].abs().sum() > 0
    for x, y in zip(*res):
        assert torch.equal(x, y)


def test_backend_choice_is_explicit_and_reported():
    scene = single_gaussian([0.0, 0.0, 0.0], scale=0.2)
    cam = look_at_camera((0.0, 0.0, -3.0))
    assert rasterize(*scene, cam)["backend"] == "tiles"  # the default for CPU tensors
    assert rasterize(*scene, cam, backend="torch")["backend"] == "torch"
    with pytest.raises(ValueError, match="backend"):
        rasterize(*scene, cam, backend="cuda_tiles")


def test_float32_bike_scene_agrees():
    """The benchmark's bike-like part in float32 (the training dtype): images to 1e-5, every
    parameter's gradient to 1e-4 relative (float32 rounding, different exp implementations)."""
    from bench.raster import bike_like_gaussians
    from splatting.raster.camera import ring_camera

    params = bike_like_gaussians(4000)
    cam = ring_camera(30.0, size=160, focal=650.0)
    res = {}
    for backend in ("tiles", "torch"):
        ps = [p.clone().requires_grad_(True) for p in params]
        out = rasterize(*ps, cam, backend=backend)
        (out["rgb"].abs().mean() + 0.01 * out["depth"].mean()).backward()
        res[backend] = (out, [p.grad for p in ps])
    (a, ga), (b, gb) = res["tiles"], res["torch"]
    assert b["alpha"].max() > 0.9
    for key in ("rgb", "alpha", "depth"):
        assert (a[key] - b[key]).abs().max() < 1e-5 * max(1.0, b[key].abs().max().item()), key
    for name, x, y in zip(("means", "quats", "scales", "opacities", "sh"), ga, gb):
        assert (x - y).norm() <= 1e-4 * y.norm(), name


def _crowded_tile_scene(n=3000, seed=11):
    """n faint, small Gaussians whose 3-sigma boxes all fall inside one 16x16 tile of a 32x32
    image (with a few reaching into the neighbours): thousands of entries in one tile list."""
    gen = torch.Generator().manual_seed(seed)
    means = torch.zeros(n, 3, dtype=F64)
    means[:, :2] = (torch.rand(n, 2, generator=gen, dtype=F64) - 0.5) * 0.12
    means[:, 2] = torch.rand(n, generator=gen, dtype=F64) * 0.5
    quats = torch.randn(n, 4, generator=gen, dtype=F64)
    scales = torch.exp(torch.rand(n, 3, generator=gen, dtype=F64) * 1.5 - 4.5)
    opac = 0.02 + 0.1 * torch.rand(n, generator=gen, dtype=F64)  # faint: the cut-off comes late
    sh = torch.randn(n, 4, 3, generator=gen, dtype=F64) * 0.3
    # 16 px per 0.12 m at 3 m: the cloud's centre lies at the image centre, tile (1, 1)'s corner
    cam = look_at_camera((0.0, 0.0, -3.0), width=32, height=32, focal=400.0, cx=24.0, cy=24.0)
    return (means, quats, scales, opac, sh), cam


def test_thousands_of_gaussians_in_one_tile():
    """No per-tile capacity: a tile list of thousands of entries composites and differentiates
    like the torch path, front to back through to the cut-off."""
    scene, cam = _crowded_tile_scene()
    bg = torch.tensor([0.3, 0.2, 0.1], dtype=F64)
    a, ga, m2a = _run("tiles", scene, cam, bg)
    b, gb, m2b = _run("torch", scene, cam, bg)
    radii = b["radii"]
    m2 = b["means2d"].detach()
    in_tile = (radii > 0) & (m2[:, 0] >= 16) & (m2[:, 0] < 32) & (m2[:, 1] >= 16) & (m2[:, 1] < 32)
    assert in_tile.sum() > 1000  # the crowd is really in one tile
    assert b["alpha"].max() > 0.999  # deep enough to reach the transmittance cut-off
    for key in ("rgb", "alpha", "depth"):
        _assert_close(a[key].detach(), b[key].detach(), f"crowded {key}")
    for pname, x, y in zip(("means", "quats", "scales", "opacities", "sh", "background"), ga, gb):
        _assert_close(x, y, f"crowded d/d{pname}")
    _assert_close(m2a, m2b, "crowded means2d.grad")


@pytest.mark.parametrize("used", ["rgb", "alpha", "depth", "features"])
def test_gradient_of_one_output_alone(used):
    """Only one output in the loss: the others' gradients reach the compositor as None (null
    pointers in C++, not zero images); the result must still match the torch path."""
    gen = torch.Generator().manual_seed(17)
    scene = random_scene(gen, 40, 1)
    cam = random_camera(gen)
    feats = torch.rand(40, 2, generator=gen, dtype=F64)
    bg = torch.tensor([0.5, 0.1, 0.7], dtype=F64)
    grads = {}
    for backend in ("tiles", "torch"):
        params = [t.clone().requires_grad_(True) for t in (*scene, feats)]
        out = rasterize(*params[:5], cam, background=bg, features=params[5], backend=backend)
        (out[used] * torch.linspace(0.5, 1.5, out[used].numel(), dtype=F64).view_as(out[used])).sum().backward()
        grads[backend] = [p.grad for p in params]
    assert grads["tiles"][0].abs().sum() > 0
    for pname, x, y in zip(("means", "quats", "scales", "opacities", "sh", "features"), grads["tiles"], grads["torch"]):
        _assert_close(x, y, f"{used} only: d/d{pname}")


def test_threads_do_not_change_a_bit_with_features_background_antialiased():
    """Bit-identical images and gradients at 1 and 2 threads with every option on, in float32."""
    from bench.raster import bike_like_gaussians
    from splatting.raster.camera import ring_camera

    params = bike_like_gaussians(4000, sh_degree=2)
    feats = torch.rand(4000, 3, generator=torch.Generator().manual_seed(4))
    bg = torch.tensor([0.2, 0.4, 0.6])
    cam = ring_camera(60.0, size=160, focal=650.0)
    old = torch.get_num_threads()
    res = []
    try:
        for nt in (1, 2, 1):
            torch.set_num_threads(nt)
            ps = [p.clone().requires_grad_(True) for p in (*params, feats)]
            out = rasterize(*ps[:5], cam, background=bg, features=ps[5], antialiased=True, backend="tiles")
            (out["rgb"].square().sum() + out["alpha"].sum() + out["depth"].sum() + out["features"].sum()).backward()
            res.append([out["rgb"], out["alpha"], out["depth"], out["features"]] + [p.grad for p in ps])
    finally:
        torch.set_num_threads(old)
    assert res[0][1].max() > 0.9 and res[0][4].abs().sum() > 0
    for other in res[1:]:
        for x, y in zip(res[0], other):
            assert torch.equal(x, y)


def test_no_grad_render_equals_the_differentiable_one():
    """Without a gradient to follow the tiled pass skips what only the backward reads (T_final,
    the last contributors, the entries' slots); the images must not change a bit."""
    from bench.raster import bike_like_gaussians
    from splatting.raster.camera import ring_camera

    params = bike_like_gaussians(3000, sh_degree=1)
    feats = torch.rand(3000, 2, generator=torch.Generator().manual_seed(5))
    ids = torch.arange(3000) % 3 - 1
    bg = torch.tensor([0.3, 0.1, 0.7])
    cam = ring_camera(30.0, size=128, focal=520.0)
    kw = dict(background=bg, features=feats, groups=(ids, 2), backend="tiles")
    ps = [p.clone().requires_grad_(True) for p in params]
    with_grad = rasterize(*ps, cam, **kw)
    with torch.no_grad():
        no_grad = rasterize(*params, cam, **kw)
    plain = rasterize(*params, cam, **kw)  # grad mode on, but nothing requires one
    assert with_grad["alpha"].max() > 0.9
    for key in ("rgb", "alpha", "depth", "features", "group_alpha"):
        assert torch.equal(with_grad[key].detach(), no_grad[key]), key
        assert torch.equal(with_grad[key].detach(), plain[key]), key


def test_antialiased_tiles_match_torch_gradients():
    """antialiased=True scales opacities before compositing: both back ends, all gradients."""
    gen = torch.Generator().manual_seed(23)
    means, quats, scales, opac, sh = random_scene(gen, 50, 2)
    scales = scales * 0.2  # mostly sub-pixel Gaussians: the compensation halves alpha or more
    cam = random_camera(gen)
    res = {}
    for backend in ("tiles", "torch"):
        ps = [t.clone().requires_grad_(True) for t in (means, quats, scales, opac, sh)]
        out = rasterize(*ps, cam, antialiased=True, backend=backend)
        (out["rgb"].sum() + out["alpha"].square().sum()).backward()
        res[backend] = (out, [p.grad for p in ps])
    (a, ga), (b, gb) = res["tiles"], res["torch"]
    assert b["alpha"].max() > 0.05
    for key in ("rgb", "alpha"):
        _assert_close(a[key].detach(), b[key].detach(), f"aa {key}")
    for pname, x, y in zip(("means", "quats", "scales", "opacities", "sh"), ga, gb):
        _assert_close(x, y, f"aa d/d{pname}")


@pytest.mark.parametrize("name,scene,cam,bg", [s for s in SCENES if s[0] != "empty"] + [
    ("crowded", *_crowded_tile_scene(), None)], ids=[s[0] for s in SCENES if s[0] != "empty"] + ["crowded"])
def test_group_alphas_equal_each_group_rendered_alone(name, scene, cam, bg):
    """groups: each group's alpha from the image's own pass equals that group's Gaussians
    rendered alone (both back ends, 1e-5), Gaussians in no group (-1) occlude but count for no
    group, and the image itself is the one rendered without groups, bit for bit."""
    n = len(scene[0])
    ids = torch.arange(n) % 3 - 1  # -1, 0, 1, -1, ...
    ids[: n // 4] = 1  # uneven groups
    plain = rasterize(*scene, cam, background=bg, backend="tiles")
    for backend in ("tiles", "torch"):
        out = rasterize(*scene, cam, background=bg, backend=backend, groups=(ids, 2))
        assert out["group_alpha"].shape == (2, cam.height, cam.width)
        for q in range(2):
            keep = ids == q
            alone = rasterize(*(t[keep] for t in scene), cam, backend="torch")["alpha"]
            _assert_close(out["group_alpha"][q], alone, f"{name} {backend} group {q}")
        if backend == "tiles":
            for key in ("rgb", "alpha", "depth"):
                assert torch.equal(out[key], plain[key]), key
    if name in ("dense_opaque", "crowded"):  # the groups really reach behind the image's cut-off
        ga = out["group_alpha"]
        assert ((ga[0] > 0.5) & (ga[1] > 0.5) & (plain["alpha"] > 0.99)).any()


def test_group_ids_out_of_range_are_refused():
    scene = single_gaussian([0.0, 0.0, 0.0], scale=0.2)
    cam = look_at_camera((0.0, 0.0, -3.0))
    with pytest.raises(ValueError, match="group"):
        rasterize(*scene, cam, groups=(torch.tensor([2]), 2))


def test_shaded_tiles_write_only_what_is_asked_and_refuse_what_they_cannot_shade():
    """rasterize(shade=TileShade(...)) (the relit tile epilogue, csrc/shade.cpp): the same alpha as a
    plain render bit for bit, the feature image only with features=True (then bit for bit the plain
    one), the colour the shaded one (not the composited colour); refused under grad, with depth,
    with a background, float64, or features of another count than the flags name."""
    from splatting.raster.cpu_tiles import TileShade
    from splatting.relight.render import shade_composited, shade_flags, shade_params
    from splatting.relight.shading import Light
    gen = torch.Generator().manual_seed(46)
    scene = [t.float() for t in random_scene(gen, 80, 0)]
    cam = random_camera(gen)
    feats = [torch.randn(80, 3, generator=gen), torch.rand(80, 1, generator=gen)]  # normal, gloss luminance
    light = Light(sun_direction=(0.2, 0.9, -0.3), sun_strength=3.0, sky=(0.3, 0.3, 0.35))
    spec = TileShade(shade_params(cam, light), shade_flags(True))
    with torch.no_grad():
        plain = rasterize(*scene, cam, features=feats, backend="tiles", depth=False)
        shaded = rasterize(*scene, cam, features=feats, backend="tiles", depth=False, shade=spec)
        both = rasterize(*scene, cam, features=feats, backend="tiles", depth=False, shade=spec._replace(features=True))
    assert "features" not in shaded and torch.equal(both["features"], plain["features"])
    assert torch.equal(shaded["alpha"], plain["alpha"]) and torch.equal(both["rgb"], shaded["rgb"])
    assert float(plain["alpha"].max()) > 0.3
    want = shade_composited(plain["rgb"], plain["features"], plain["alpha"], cam, light, gloss=True, backend="torch")
    torch.testing.assert_close(shaded["rgb"], want, atol=2e-5, rtol=1e-4)
    assert float((shaded["rgb"] - plain["rgb"]).abs().max()) > 0.05
    old = torch.get_num_threads()  # tiles shaded by two threads: the same bits
    torch.set_num_threads(2)
    try:
        with torch.no_grad():
            two = rasterize(*scene, cam, features=feats, backend="tiles", depth=False, shade=spec)
    finally:
        torch.set_num_threads(old)
    assert torch.equal(two["rgb"], shaded["rgb"]) and torch.equal(two["alpha"], shaded["alpha"])
    with torch.no_grad():
        for kw, what in ((dict(depth=True), "depth=False"), (dict(background=torch.ones(3)), "a background"),
                         (dict(features=feats[:1]), "6 channels where flags 1 need 7")):
            with pytest.raises(ValueError, match=what):
                rasterize(*scene, cam, **{"features": feats, "backend": "tiles", "depth": False, "shade": spec, **kw})
        with pytest.raises(ValueError, match="not float32"):
            rasterize(*[t.double() for t in scene], cam, features=[f.double() for f in feats], backend="tiles",
                      depth=False, shade=spec)
    with pytest.raises(ValueError, match="a gradient is wanted"):
        rasterize(scene[0].clone().requires_grad_(True), *scene[1:], cam, features=feats, backend="tiles",
                  depth=False, shade=spec)

"""Relightable Gaussians on the torch side: Lambert shading, normals posed with their part, the fit
recovering known albedo and normals, the relight-fit command's bad input."""
import math
import subprocess
import sys

import numpy as np
import pytest
import torch

from cyclist_formats import bike_folder
from splatting.gaussians.container import Gaussians
from splatting.raster.camera import ring_camera
from splatting.relight.bike import RelightableBike
from splatting.relight.render import composite_features, prepare, relit_static, render_relit
from splatting.relight.shading import Light, ggx_sun, lambert_reference, shade, shade_linear, srgb_encode, view_directions
from helpers import axis_splats, level_grid, make_bike, pass_views, mat_vec, random_pose, ref_part_R


def test_lambert_by_hand():
    # a white-ish surface facing straight up, the sun 60 deg from the zenith: cos = 0.5
    light = Light(sun_direction=(math.sin(math.radians(60)), math.cos(math.radians(60)), 0.0),
                  sun_colour=(1.0, 0.5, 0.25), sun_strength=math.pi, sky=(0.1, 0.2, 0.3))
    alb = torch.tensor([[[0.8, 0.6, 0.4]]])
    out = shade_linear(alb, torch.tensor([[[0.0, 1.0, 0.0]]]), light)[0, 0]
    expect = [0.8 * (0.5 * 1.0 + 0.1), 0.6 * (0.5 * 0.5 + 0.2), 0.4 * (0.5 * 0.25 + 0.3)]
    np.testing.assert_allclose(out.numpy(), expect, rtol=1e-6)
    # facing away from the sun: the sky only
    back = shade_linear(alb, torch.tensor([[[0.0, -1.0, 0.0]]]), light)[0, 0]
    np.testing.assert_allclose(back.numpy(), [0.08, 0.12, 0.12], rtol=1e-6)


def test_shading_matches_the_formula_for_random_normals():
    rng = np.random.default_rng(1)
    for _ in range(20):
        light = Light(sun_direction=tuple(rng.normal(size=3)), sun_colour=tuple(rng.uniform(0.5, 1, 3)),
                      sun_strength=float(rng.uniform(1, 5)), sky=tuple(rng.uniform(0, 0.5, 3)))
        a, n = rng.uniform(0, 1, 3), rng.normal(size=3)
        # composited normals are premultiplied and not unit: only the direction may matter
        got = shade_linear(torch.tensor(a)[None, None], torch.tensor(0.37 * n)[None, None], light)[0, 0]
        np.testing.assert_allclose(got.numpy(), lambert_reference(a, n, light), rtol=1e-6, atol=1e-9)


def test_display_colour_is_srgb_of_the_straight_colour_times_coverage():
    light = Light(sun_direction=(0, 1, 0), sun_strength=math.pi, sky=(0, 0, 0))
    alpha = torch.tensor([[0.5]])
    out = shade(torch.tensor([[[0.2, 0.2, 0.2]]]), torch.tensor([[[0.0, 0.5, 0.0]]]), alpha, light)
    # straight albedo 0.4, E cos / pi = 1 -> linear 0.4 -> sRGB 0.6652 -> times alpha 0.5
    np.testing.assert_allclose(out[0, 0].numpy(), [0.5 * 0.66519] * 3, atol=2e-4)
    assert float(srgb_encode(torch.tensor(0.4))) == pytest.approx(0.66519, abs=1e-4)


def test_gloss_reflects_the_sky_and_peaks_in_the_mirror_direction():
    light = Light(sun_direction=(1.0, 1.0, 0.0), sun_colour=(1.0, 1.0, 1.0), sun_strength=2.0, sky=(0.2, 0.3, 0.4))
    up = torch.tensor([[[0.0, 1.0, 0.0]]])
    gloss, zero = torch.tensor([[[0.5, 0.5, 0.5]]]), torch.zeros(1, 1, 3)
    mirror = torch.tensor([[[-1.0, 1.0, 0.0]]]) / math.sqrt(2)   # the sun's reflection about "up"
    # no highlight: the sky's glossy reflection is exactly colour x sky
    flat = shade_linear(zero, up, light, gloss, mirror, highlight=0.0)[0, 0]
    np.testing.assert_allclose(flat.numpy(), [0.1, 0.15, 0.2], rtol=1e-6)
    # GGX by hand at the peak: n.h = 1 -> D = 1 / (pi a^2), a = r^2; n.v = cos 45
    r = 0.4
    peak = float(ggx_sun(up[0, 0], mirror[0, 0], light, r))
    assert peak == pytest.approx(1 / (math.pi * r ** 4) / (4 * math.cos(math.pi / 4)), rel=1e-5)
    # off the mirror direction it falls; below the horizon of the sun there is none
    off = float(ggx_sun(up[0, 0], torch.tensor([0.0, 1.0, 0.0]), light, r))
    assert 0 < off < 0.2 * peak
    assert float(ggx_sun(-up[0, 0], torch.tensor([0.0, -1.0, 0.0]), light, r)) == 0.0


def test_view_directions_point_at_the_camera():
    cam = ring_camera(30.0, (0.0, 0.5, 0.0), size=64)
    v = view_directions(cam, torch.float64)
    # every pixel's direction, followed from the orbit plane's point it sees, reaches the camera centre:
    # so all of them are unit and the centre pixel's is (centre - orbit point) normalised
    assert torch.allclose(v.norm(dim=-1), torch.ones(64, 64, dtype=torch.float64))
    c = cam.centre.double()
    expect = (c - torch.tensor([0.0, 0.5, 0.0], dtype=torch.float64))
    expect = expect / expect.norm()
    mid = (v[31, 31] + v[32, 32] + v[31, 32] + v[32, 31]) / 4
    assert torch.allclose(mid / mid.norm(), expect, atol=1e-3)


def test_normals_turn_with_their_part(tmp_path):
    d = make_bike(tmp_path)
    g = torch.Generator().manual_seed(0)
    for part in ("frame", "steering", "crank"):
        from splatting.gaussians.container import read_ply

        n = len(read_ply(bike_folder.gaussians_path(d, part)))
        nrm = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
        bike_folder.write_relight(bike_folder.gaussians_path(d, part), torch.rand(n, 3).numpy(), nrm.numpy(),
                                  torch.rand(n, 3).numpy())
    bike = RelightableBike.load(d)
    rng = np.random.default_rng(3)
    for _ in range(3):
        pose = random_pose(rng)
        _, albedo, world, gloss = bike.pose(torch.tensor(pose, dtype=torch.float64))
        for name, (a, e) in zip(bike.model.part_names, bike.model.ranges):
            R = ref_part_R(name, pose)
            for i in (a, (a + e) // 2, e - 1):
                expect = mat_vec(R, bike.normals[i].tolist())
                np.testing.assert_allclose(world[i].numpy(), expect, atol=1e-5)
        assert torch.equal(albedo, bike.albedo) and torch.equal(gloss, bike.gloss)  # colours do not turn


def test_relight_file_must_match_the_part(tmp_path):
    d = make_bike(tmp_path)
    p = bike_folder.gaussians_path(d, "frame")
    with pytest.raises(bike_folder.UserError, match="missing"):
        bike_folder.read_relight(p)
    bike_folder.write_relight(p, np.zeros((5, 3)), np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(bike_folder.UserError, match="do not match 200"):
        bike_folder.read_relight(p, n=200)


def _flat_patch(n_side=14, seed=0):
    """A 1 m square of flat splats in the plane z = 0, facing the ring's view 0 (-Z) and view 18 (+Z)."""
    g = torch.Generator().manual_seed(seed)
    u = torch.linspace(-0.5, 0.5, n_side)
    xy = torch.stack(torch.meshgrid(u, u, indexing="ij"), -1).reshape(-1, 2)
    n = len(xy)
    means = torch.cat([xy, torch.zeros(n, 1)], 1) + torch.tensor([0.0, 1.0, 0.0])
    ls = torch.log(torch.tensor([0.06, 0.06, 0.002])).repeat(n, 1)
    return Gaussians(means, torch.tensor([1.0, 0, 0, 0]).repeat(n, 1), ls, torch.full((n,), 3.0),
                     torch.randn(n, 1, 3, generator=g) * 0.1)


def test_fit_recovers_albedo_and_normals(monkeypatch):
    import splatting.relight.fit as fit
    from splatting.relight.fit import RelightFitConfig, fit_relight

    g = _flat_patch()
    n = len(g)
    true_alb = torch.where(g.means[:, :1] > 0, torch.tensor([0.7, 0.2, 0.1]), torch.tensor([0.1, 0.3, 0.6]))
    true_nrm = torch.tensor([0.0, 0.0, -1.0]).repeat(n, 1)
    true_gl = torch.where(g.means[:, 1:2] > 1, torch.tensor([0.3, 0.3, 0.3]), torch.tensor([0.05, 0.05, 0.05]))
    views, targets = pass_views(g, true_alb, true_nrm, true_gl)
    monkeypatch.setattr(fit, "load_pass_targets", lambda v, s: targets)
    feats, m = fit_relight(g, views, RelightFitConfig(iterations=150, holdout=(2,), progress=False))
    alb, nrm = feats["albedo"], feats["normal"]
    vis = (g.means[:, 0].abs() < 0.45) & ((g.means[:, 1] - 1).abs() < 0.45)  # edge splats: partial coverage
    assert (alb[vis] - true_alb[vis]).abs().max() < 0.05
    assert (feats["gloss"][vis] - true_gl[vis]).abs().max() < 0.05
    # the initial normal is the shortest axis turned away from the centroid: +-Z, so this also
    # checks the fit flips a wrong sign
    assert float((nrm[vis] * true_nrm[vis]).sum(-1).min()) > 0.98
    assert m["heldout_albedo_psnr"] > 35 and m["heldout_gloss_psnr"] > 35 and m["heldout_normal_err_deg"] < 3


def test_relit_render_of_a_lit_patch():
    g = _flat_patch()
    alb = torch.full((len(g), 3), 0.5)
    nrm = torch.tensor([0.0, 0.0, -1.0]).repeat(len(g), 1)
    cam = ring_camera(0, orbit_centre=(0, 1, 0), size=64, focal=2084.97 * 64 / 512 * 2)
    lit = render_relit(g, alb, nrm, cam, Light(sun_direction=(0, 0, -1), sun_strength=math.pi, sky=(0, 0, 0)))
    dark = render_relit(g, alb, nrm, cam, Light(sun_direction=(0, 0, 1), sun_strength=math.pi, sky=(0.1, 0.1, 0.1)))
    inside = lit["alpha"] > 0.99
    assert inside.sum() > 200
    # sun head-on: linear 0.5 -> sRGB 0.7354; sun behind, sky 0.1: linear 0.05 -> sRGB 0.2478
    np.testing.assert_allclose(lit["rgb"][inside].numpy(), 0.7354, atol=0.01)
    np.testing.assert_allclose(dark["rgb"][inside].numpy(), 0.2478, atol=0.01)


def test_relit_channels_equal_the_pair_list_compositing():
    # render_relit composites the reflectance through the colour channels (degree-0 SH) and the
    # normals as features of the tiled rasterizer; the fit composites them over the torch pair
    # list: the two must agree, or what was fitted is not what is rendered
    g = _flat_patch()
    gen = torch.Generator().manual_seed(2)
    g = g.map(lambda x: x)
    g.opacity_logits = torch.randn(len(g), generator=gen)  # semi-transparent: T and the cut-offs matter
    g.means = g.means + 0.05 * torch.randn(len(g), 3, generator=gen)
    cam = ring_camera(20, orbit_centre=(0, 1, 0), size=48, focal=2084.97 * 48 / 512 * 2)
    alb, gl = torch.rand(len(g), 3, generator=gen) * 0.8, torch.rand(len(g), 3, generator=gen) * 0.1
    nrm = torch.nn.functional.normalize(torch.randn(len(g), 3, generator=gen), dim=-1)
    out = render_relit(g, alb, nrm, cam, Light(), gl, antialiased=False, reflectance=True, normal=True)
    (R, n), alpha = composite_features(prepare(g, cam), [alb + gl, nrm])
    assert float(alpha.max()) > 0.5
    torch.testing.assert_close(out["alpha"], alpha, atol=2e-4, rtol=1e-3)
    torch.testing.assert_close(out["reflectance"], R, atol=2e-4, rtol=1e-3)
    torch.testing.assert_close(out["normal"], n, atol=2e-4, rtol=1e-3)
    # the pose-invariant channels kept by the caller (RelightableBike.static) render the same, bit for bit
    kept = render_relit(g, None, nrm, cam, Light(), None, antialiased=False, static=relit_static(alb, gl), normal=True,
                        fused=False)
    for k in ("rgb", "alpha", "normal"):  # (and the shading in place over the reflectance: the same colours)
        assert torch.equal(kept[k], out[k]), k
    with pytest.raises(ValueError, match="static channels for 99 Gaussians"):
        render_relit(g, alb, nrm, cam, Light(), gl, static=relit_static(alb[:99], gl[:99]))


@pytest.mark.parametrize("gloss, shadows, sky", [(True, False, True), (False, True, False), (True, True, True),
                                                 (False, False, False)])
def test_relit_render_shaded_in_the_compositor_equals_two_passes(gloss, shadows, sky):
    # render_relit's default: the compositor shades each tile as it finishes it (csrc/shade.cpp
    # rl_shade_tile_f32) and writes no reflectance or feature image; against the two-pass path
    # (composite, then shade_composited's C loop) and against the torch pair list shaded by the
    # torch formula.  45 x 37 px: edge tiles, and rows not a multiple of the 8 SIMD lanes.
    from splatting.relight.render import gloss_luma, shade_composited
    from splatting.relight.shadow import sun_visibility
    g = _flat_patch(seed=3)
    gen = torch.Generator().manual_seed(4)
    g.opacity_logits = torch.randn(len(g), generator=gen)  # semi-transparent: partly covered pixels
    g.means = g.means + 0.05 * torch.randn(len(g), 3, generator=gen)
    cam = ring_camera(20, orbit_centre=(0, 1, 0), size=45, focal=2084.97 * 45 / 512 * 2)
    cam = type(cam)(cam.R, cam.T, cam.K, 45, 37, "c")
    alb = torch.rand(len(g), 3, generator=gen) * 0.8
    gl = torch.rand(len(g), 3, generator=gen) * 0.2 if gloss else None
    nrm = torch.nn.functional.normalize(torch.randn(len(g), 3, generator=gen) + torch.tensor([0, 0, -2.0]), dim=-1)
    skv = torch.rand(len(g), generator=gen) if sky else None
    light = Light(sun_direction=(0.3, 0.5, -0.8), sun_strength=4.0, sky=(0.2, 0.25, 0.3))
    kw = dict(antialiased=False, shadows=shadows, sky_visibility=skv)
    fused = render_relit(g, alb, nrm, cam, light, gl, normal=True, **kw)
    two = render_relit(g, alb, nrm, cam, light, gl, normal=True, fused=False, **kw)
    assert set(fused) == {"rgb", "alpha", "normal"}
    assert torch.equal(fused["alpha"], two["alpha"]) and torch.equal(fused["normal"], two["normal"])
    torch.testing.assert_close(fused["rgb"], two["rgb"], atol=1e-5, rtol=0)
    cover = fused["alpha"] > 1e-5
    assert 200 < int(cover.sum()) < 45 * 37 and float(fused["rgb"][cover].max()) > 0.2
    assert float(fused["rgb"][~cover].abs().max()) == 0.0
    # the reference: channels composited over the torch pair list, shaded by the torch formula
    cols = [nrm] + ([gloss_luma(gl)] if gloss else []) + ([sun_visibility(g, light)[:, None]] if shadows else []) \
        + ([skv[:, None]] if sky else [])
    refl = alb if gl is None else alb + gl
    (R, F), alpha = composite_features(prepare(g, cam), [refl, torch.cat(cols, 1)])
    ref = shade_composited(R, F, alpha, cam, light, gloss, False, shadows, backend="torch", sky_channel=sky)
    torch.testing.assert_close(fused["alpha"], alpha, atol=2e-4, rtol=1e-3)
    torch.testing.assert_close(fused["rgb"], ref, atol=1e-3, rtol=1e-3)
    # the normal is written only when asked for; the composited reflectance only by the two passes
    assert set(render_relit(g, alb, nrm, cam, light, gl, **kw)) == {"rgb", "alpha"}
    with pytest.raises(ValueError, match="fused shading needs"):
        render_relit(g, alb, nrm, cam, light, gl, reflectance=True, fused=True, **kw)


def test_relight_fit_command_bad_input(tmp_path):
    r = subprocess.run([sys.executable, "-m", "splatting", "relight-fit", "--views", str(tmp_path / "nope")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "views folder not found" in r.stderr and r.stderr.count("\n") == 1
    r = subprocess.run([sys.executable, "-m", "splatting", "relight-fit", "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "--views" in r.stdout


def test_cast_shadow_of_a_blob_on_a_plane():
    from splatting.relight.shadow import sun_visibility

    # a 1 m plane of flat Gaussians in two layers 2 mm apart (a surface must not shadow itself)
    # and a 0.2 m blob 0.3 m above its centre; sun straight overhead, then from 45 degrees
    xs = torch.linspace(-0.5, 0.5, 41)
    X, Z = torch.meshgrid(xs, xs, indexing="ij")
    plane = torch.stack([X.reshape(-1), torch.zeros(X.numel()), Z.reshape(-1)], 1)
    plane = torch.cat([plane, plane - torch.tensor([0.0, 0.002, 0.0])])
    g0 = torch.Generator().manual_seed(0)
    blob = torch.randn(300, 3, generator=g0) * 0.04 + torch.tensor([0.0, 0.3, 0.0])
    means = torch.cat([plane, blob])
    n = len(means)
    scales = torch.cat([torch.tensor([[0.02, 0.002, 0.02]]).expand(len(plane), 3), torch.full((300, 3), 0.03)])
    g = Gaussians(means, torch.tensor([[1.0, 0.0, 0.0, 0.0]]).expand(n, 4).contiguous(), torch.log(scales),
                  torch.full((n,), 4.0), torch.zeros(n, 1, 3))
    for d in ((0.0, 1.0, 0.0), (1.0, 1.0, 0.0)):
        vis = sun_visibility(g, Light(sun_direction=d))
        l = torch.tensor(d) / torch.tensor(d).norm()
        # where the blob's centre casts its shadow on the plane (y = 0)
        c = torch.tensor([0.0, 0.3, 0.0]) - l * (0.3 / float(l[1]))
        r_shadow = (plane - c).norm(dim=-1)
        under = r_shadow < 0.05
        far = r_shadow > 0.3
        assert under.sum() >= 4 and far.sum() > 100
        assert float(vis[: len(plane)][under].max()) < 0.2
        assert float(vis[: len(plane)][far].min()) > 0.9
        top = int((blob @ l).argmax())  # the blob's most sunward Gaussian is lit (those below its
        assert float(vis[len(plane) + top]) > 0.9  # 3 cm footprint are, rightly, in its shadow)


@pytest.mark.parametrize("gloss, rough, shadows, sky", [(True, False, False, False), (True, True, True, True),
                                                       (False, False, True, False), (True, False, False, True)])
def test_fused_shading_equals_the_torch_formula(gloss, rough, shadows, sky):
    # shade_composited's C loop (csrc/shade.cpp) against its torch reference, on channels as the
    # compositor leaves them: strided (H, W, C) views of one table, partly covered pixels
    from splatting.relight.render import shade_composited
    gen = torch.Generator().manual_seed(5)
    H, W = 24, 40
    C = 3 + 3 + int(gloss) + int(rough) + int(shadows) + int(sky)
    table = torch.rand(H, W, C + 2, generator=gen)
    alpha = torch.rand(H, W, generator=gen) * (torch.rand(H, W, generator=gen) > 0.3)
    alpha[0, :5] = torch.tensor([0.0, 1e-6, 2e-5, 0.5, 1.0])
    R = table[..., 1:4] * alpha[..., None]
    feats = table[..., 4:4 + C - 3].clone()
    feats[..., :3] = torch.randn(H, W, 3, generator=gen)  # composited normals: any length, any sign
    table[..., 4:4 + C - 3] = feats * alpha[..., None] if (rough or shadows or sky) else feats
    feats = table[..., 4:4 + C - 3]
    cam = ring_camera(35, orbit_centre=(0, 1, 0), size=W, focal=50.0)
    cam = type(cam)(cam.R, cam.T, cam.K, W, H, "c")
    light = Light(sun_direction=(0.3, 0.8, -0.5), sun_colour=(1.0, 0.9, 0.8), sun_strength=4.0, sky=(0.2, 0.25, 0.3))
    kw = dict(gloss=gloss, rough_channel=rough, shadows=shadows, roughness=0.4, highlight=0.25, sky_channel=sky)
    c = shade_composited(R, feats, alpha, cam, light, backend="c", **kw)
    t = shade_composited(R, feats, alpha, cam, light, backend="torch", **kw)
    assert float(t.abs().max()) > 0.1 and int((t.sum(-1) > 0).sum()) > 0.5 * H * W
    torch.testing.assert_close(c, t, atol=2e-5, rtol=1e-4)
    box = (5, 3, 30, 20)  # (u0, v0, u1, v1): only these pixels are shaded
    cb = shade_composited(R, feats, alpha, cam, light, backend="c", box=box, **kw)
    torch.testing.assert_close(cb, shade_composited(R, feats, alpha, cam, light, backend="torch", box=box, **kw),
                               atol=2e-5, rtol=1e-4)
    torch.testing.assert_close(cb[3:20, 5:30], c[3:20, 5:30])
    assert float(cb.sum()) < float(c.sum()) and float(cb[:3].abs().sum() + cb[:, :5].abs().sum()) == 0
    # in place over the reflectance (render_relit's default): the same colours, in R's own memory
    for backend, want in (("c", c), ("torch", t)):
        Rc = R.clone()
        got = shade_composited(Rc, feats, alpha, cam, light, backend=backend, in_place=True, **kw)
        assert got.data_ptr() == Rc.data_ptr() and torch.equal(got, want), backend
    with pytest.raises(ValueError, match="in_place"):
        shade_composited(table[..., 1:4], feats, alpha, cam, light, in_place=True, **kw)  # a strided view
    if sky:  # the sky channel darkens: without it every pixel sees the whole sky
        kw0 = dict(kw, sky_channel=False)
        t0 = shade_composited(R, feats[..., :-1], alpha, cam, light, backend="torch", **kw0)
        assert float((t0 - t).min()) >= -1e-6 and float((t0 - t).max()) > 0.01


def test_sky_term_scaled_by_the_sky_visibility():
    # by hand: albedo a, sun behind the surface, so only the sky lights it: a * sky * V
    light = Light(sun_direction=(0.0, -1.0, 0.0), sun_strength=3.0, sky=(0.2, 0.3, 0.4))
    a = torch.tensor([[[0.5, 0.6, 0.7]]])
    n = torch.tensor([[[0.0, 1.0, 0.0]]])
    out = shade_linear(a, n, light, sky_visibility=torch.tensor([[[0.25]]]))
    torch.testing.assert_close(out, a * torch.tensor([0.2, 0.3, 0.4]) * 0.25)
    torch.testing.assert_close(shade_linear(a, n, light), a * torch.tensor([0.2, 0.3, 0.4]))


def test_sky_visibility_under_a_roof():
    from splatting.relight.shadow import sky_visibility

    # a 1 m floor of flat Gaussians facing up and a 0.4 m roof 0.1 m above its centre: under the
    # roof's middle it hides ~sin^2(63 deg) = 0.8 of the cosine-weighted sky; far from it, nothing;
    # the roof's top sees the whole sky
    floor, roof = level_grid(0.5, 41, 0.0), level_grid(0.2, 17, 0.1)
    g = axis_splats(torch.cat([floor, roof]), [0.02, 0.002, 0.02])
    up = torch.tensor([[0.0, 1.0, 0.0]]).expand(len(g), 3)
    vis = sky_visibility(g, up)
    r = floor[:, [0, 2]].norm(dim=-1)
    assert float(vis[: len(floor)][r < 0.05].max()) < 0.3
    assert float(vis[: len(floor)][r > 0.45].min()) > 0.85
    assert float(vis[len(floor):].min()) > 0.9


def test_shading_loss_sees_the_direction_of_the_composited_normal():
    from splatting.relight.fit import shading_loss
    gen = torch.Generator().manual_seed(3)
    target = torch.nn.functional.normalize(torch.randn(6, 7, 3, generator=gen), dim=-1) * 0.9  # premultiplied
    alpha = torch.full((6, 7), 0.9)
    dirs = torch.nn.functional.normalize(torch.randn(8, 3, generator=gen), dim=-1)
    # the same direction at another length (Gaussians disagreeing inside the pixel) shades the same
    assert float(shading_loss(target * 0.6, alpha, target, dirs)) < 1e-6
    turned = torch.nn.functional.normalize(target + 0.5 * torch.randn(6, 7, 3, generator=gen), dim=-1) * 0.9
    assert float(shading_loss(turned, alpha, target, dirs)) > 0.05
    # half the coverage: the shading of what is there is half as bright
    assert float(shading_loss(target, alpha * 0.5, target, dirs)) > 0.05


def test_relit_loss_shades_as_the_renderer_and_differentiates():
    # the fit's differentiable display colour must be shading.shade's formula (what render_relit
    # shows), and relit_loss must pull a turned normal back towards the pass's
    from splatting.relight.fit import _display, relit_loss
    from splatting.relight.shading import random_light, shade
    from splatting.training.targets import crop_camera

    gen = torch.Generator().manual_seed(5)
    H, W = 9, 11
    cam = ring_camera(40, orbit_centre=(0, 1, 0), size=64, focal=2084.97 * 64 / 512 * 2)
    alpha = torch.rand(H, W, generator=gen) * 0.9 + 0.1
    alb = torch.rand(H, W, 3, generator=gen) * 0.6 * alpha[..., None]
    gl = torch.rand(H, W, 3, generator=gen) * 0.3 * alpha[..., None]
    nrm = torch.nn.functional.normalize(torch.randn(H, W, 3, generator=gen), dim=-1) * alpha[..., None]
    cam = crop_camera(cam, (20, 30, 20 + W, 30 + H))  # the fit's crop cameras: view directions off-centre
    light = random_light(np.random.default_rng(4))
    view = view_directions(cam)
    sun = torch.tensor(light.sun_colour) * light.sun_strength
    want = shade(alb, nrm, alpha, light, gl, view)
    got = _display(alb, gl, nrm, alpha, light, view, sun, torch.tensor(light.sky))
    torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-4)
    target = {"albedo": alb, "gloss": gl, "normal": nrm}
    assert float(relit_loss((alb, nrm, gl), alpha, target, alpha, cam, light)) < 1e-6
    turned = (nrm + 0.6 * torch.randn(H, W, 3, generator=gen)).requires_grad_(True)
    loss = relit_loss((alb, turned, gl), alpha, target, alpha, cam, light)
    assert float(loss.detach()) > 0.01
    loss.backward()
    stepped = (turned - 0.05 * turned.grad / turned.grad.abs().max()).detach()
    assert float(relit_loss((alb, stepped, gl), alpha, target, alpha, cam, light)) < float(loss.detach())


def test_view_normals_of_a_tube_turn_with_the_view():
    # normal_view = k (I - a a^T), normal 0: the mean normal of a tube's visible half, the view
    # direction's part across the axis a; normal_view 0 leaves the normals as they are
    from splatting.relight.render import view_normals

    gen = torch.Generator().manual_seed(2)
    n = 50
    means = torch.randn(n, 3, generator=gen) * 0.2 + torch.tensor([0.0, 1.0, 0.0])
    a = torch.nn.functional.normalize(torch.randn(n, 3, generator=gen), dim=-1)
    B = 2.0 * (torch.eye(3) - a[:, :, None] * a[:, None, :])
    cam = ring_camera(70, orbit_centre=(0, 1, 0), size=64)
    v = torch.nn.functional.normalize(cam.centre.float().reshape(1, 3) - means, dim=-1)
    want = torch.nn.functional.normalize(v - (v * a).sum(-1, keepdim=True) * a, dim=-1)
    torch.testing.assert_close(view_normals(torch.zeros(n, 3), B, means, cam), want, atol=1e-5, rtol=0)
    n0 = torch.nn.functional.normalize(torch.randn(n, 3, generator=gen), dim=-1)
    torch.testing.assert_close(view_normals(n0, torch.zeros(n, 3, 3), means, cam), n0, atol=1e-6, rtol=0)
    # the render's path (float32, no gradient: csrc/shade.cpp) against the fit's (torch, float64)
    B = torch.randn(n, 3, 3, generator=gen)
    c_path = view_normals(n0, B, means, cam)
    torch_path = view_normals(n0.double(), B.double(), means.double(), cam)
    assert c_path.dtype == torch.float32 and torch_path.dtype == torch.float64
    torch.testing.assert_close(c_path.double(), torch_path, atol=1e-5, rtol=0)
    Bg = B.clone().requires_grad_(True)  # with a gradient wanted: the torch path, differentiable
    view_normals(n0, Bg, means, cam).sum().backward()
    assert Bg.grad is not None and float(Bg.grad.abs().sum()) > 0


def test_view_normals_turn_with_their_part(tmp_path):
    # posed_normal_view (R B R^T per part) in the world equals the part's own normal seen from the
    # camera's direction turned into the part's frame, turned back: n_w = R normalize(n + B R^T v)
    from splatting.gaussians.container import read_ply
    from splatting.relight.render import view_normals

    d = make_bike(tmp_path)
    g = torch.Generator().manual_seed(1)
    for part in ("frame", "steering", "crank"):
        n = len(read_ply(bike_folder.gaussians_path(d, part)))
        bike_folder.write_relight(bike_folder.gaussians_path(d, part), torch.rand(n, 3).numpy(),
                                  torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1).numpy(),
                                  torch.rand(n, 3).numpy(), torch.randn(n, 3, 3, generator=g).numpy())
    bike = RelightableBike.load(d)
    assert bike.normal_view is not None and bike.normal_view.shape == (len(bike.model), 3, 3)
    cam = ring_camera(120, orbit_centre=(0, 0.5, 0), size=64)
    rng = np.random.default_rng(7)
    for _ in range(2):
        pose = torch.tensor(random_pose(rng), dtype=torch.float64)
        posed, _, world, _ = bike.pose(pose)
        means = posed.gaussians.means.float()
        got = view_normals(world, bike.posed_normal_view(pose), means, cam)
        v = torch.nn.functional.normalize(cam.centre.float().reshape(1, 3) - means, dim=-1)
        T = bike.model.part_transforms(pose)
        for name, (a, e) in zip(bike.model.part_names, bike.model.ranges):
            R = T[name][0, :3, :3].float()
            own = torch.nn.functional.normalize(
                bike.normals[a:e] + torch.einsum("nij,nj->ni", bike.normal_view[a:e], v[a:e] @ R), dim=-1)
            torch.testing.assert_close(got[a:e], own @ R.T, atol=2e-5, rtol=0)


def test_view_normals_file_round_trip_and_refusals(tmp_path):
    d = make_bike(tmp_path)
    p = bike_folder.gaussians_path(d, "frame")
    z = np.zeros((5, 3))
    bike_folder.write_relight(p, z, z, z)
    assert "normal_view" not in bike_folder.read_relight(p, n=5)  # optional: a plain fit has none
    B = np.arange(45, dtype=np.float32).reshape(5, 3, 3)
    bike_folder.write_relight(p, z, z, z, B)
    np.testing.assert_array_equal(bike_folder.read_relight(p, n=5)["normal_view"], B)
    with pytest.raises(ValueError, match="normal_view"):
        bike_folder.write_relight(p, z, z, z, B[:4])
    with open(bike_folder.relight_path(p), "wb") as f:
        np.savez(f, albedo=z, normal=z, gloss=z, normal_view=B[:, :2])
    with pytest.raises(bike_folder.UserError, match="normal_view"):
        bike_folder.read_relight(p, n=5)


def _tube_passes(monkeypatch):
    """_tube() and its ring views whose normal pass is the tube's visible half's mean normal: the
    view direction across the axis (y), so it turns with the view; the fit reads those targets."""
    import splatting.relight.fit as fit

    g = _tube()
    n = len(g)

    def across(cam):
        v = cam.centre.float().reshape(1, 3) - g.means
        return torch.nn.functional.normalize(v * torch.tensor([1.0, 0.0, 1.0]), dim=-1)

    views, targets = pass_views(g, torch.full((n, 3), 0.5), across, torch.full((n, 3), 0.04))
    monkeypatch.setattr(fit, "load_pass_targets", lambda v, s: targets)
    return g, views


def _tube(n=24):
    """A vertical row of round splats at x = z = 0 (a tube seen across), y 0.6..1.4."""
    y = torch.linspace(0.6, 1.4, n)
    means = torch.stack([torch.zeros(n), y, torch.zeros(n)], 1)
    ls = torch.log(torch.tensor([0.05, 0.04, 0.05])).repeat(n, 1)
    return Gaussians(means, torch.tensor([1.0, 0, 0, 0]).repeat(n, 1), ls, torch.full((n,), 3.0), torch.zeros(n, 1, 3))


@pytest.mark.parametrize("view_normals", [False, True])
def test_fit_learns_the_view_dependent_normal_of_a_tube(monkeypatch, view_normals):
    # passes whose normal is the tube's visible half's mean normal (the view direction across the
    # axis, so it turns 60 deg over the ring's views): one normal per Gaussian cannot follow it,
    # the view-dependent ones do, on the held-out view too
    from splatting.relight.fit import RelightFitConfig, fit_relight

    g, views = _tube_passes(monkeypatch)
    feats, m = fit_relight(g, views, RelightFitConfig(iterations=150, holdout=(1,), progress=False,
                                                     shading_loss=0.0, view_normals=view_normals))
    assert ("normal_view" in feats) is view_normals
    if view_normals:
        assert m["heldout_normal_err_deg"] < 3
    else:
        assert m["heldout_normal_err_deg"] > 6


def test_view_normal_penalty_keeps_the_smallest_turn_that_explains_the_views(monkeypatch):
    # the ring's views pin B only along the directions they see the tube from; the penalty on
    # mean(B^2) keeps B small where the views leave it free, at little cost in the views
    from splatting.relight.fit import RelightFitConfig, fit_relight

    g, views = _tube_passes(monkeypatch)
    size, err = {}, {}
    for w in (0.0, 0.05):
        feats, m = fit_relight(g, views, RelightFitConfig(iterations=150, holdout=(1,), progress=False, shading_loss=0.0,
                                                         view_normals=True, view_normal_penalty=w))
        size[w], err[w] = float(feats["normal_view"].square().mean()), m["heldout_normal_err_deg"]
    assert size[0.05] < 0.7 * size[0.0]
    assert err[0.05] < 4


def test_fit_of_sh_degree_2_parts_reads_only_their_base_colour(monkeypatch):
    # fine-tuned parts may carry SH degree 2 (issue 14's best bike): the relight fit starts the
    # albedo from the DC colour only, so the view-dependent bands change nothing in its channels
    import splatting.relight.fit as fit
    from splatting.relight.fit import RelightFitConfig, fit_relight

    g0 = _flat_patch()
    n = len(g0)
    bands = torch.randn(n, 8, 3, generator=torch.Generator().manual_seed(3)) * 0.3
    g2 = Gaussians(g0.means, g0.quats, g0.log_scales, g0.opacity_logits, torch.cat([g0.sh, bands], 1))
    assert g2.sh_degree == 2
    views, targets = pass_views(g0, torch.full((n, 3), 0.4), torch.tensor([0.0, 0.0, -1.0]).repeat(n, 1),
                                torch.full((n, 3), 0.04))
    monkeypatch.setattr(fit, "load_pass_targets", lambda v, s: targets)
    cfg = RelightFitConfig(iterations=20, holdout=(2,), progress=False, view_normals=True, relit_loss=3.0)
    f0, _ = fit_relight(g0, views, cfg)
    f2, _ = fit_relight(g2, views, cfg)
    for k in ("albedo", "normal", "gloss", "normal_view"):
        assert torch.equal(f0[k], f2[k]), k

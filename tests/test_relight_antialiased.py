"""Relighting Gaussians trained with the rasterizer's mip filter (rasterize(antialiased=...)): the
relight fit composites their fixed geometry through the filter as the render does, the shadow maps
draw them with it, and `relight-fit --bike` fits a trained bike's parts with the flag its parts
were trained with."""
import json
import os
import subprocess
import sys

import pytest
import torch

from splatting.gaussians.container import Gaussians
from splatting.raster.camera import ring_camera
from splatting.relight.render import composite_features, prepare, render_relit
from splatting.relight.shading import Light
from helpers import axis_splats, level_grid, make_bike, pass_views

FOCAL = 2084.97 * 64 / 512 * 2


def _spokes(seed=0, n_spokes=6, per=40):
    """Spoke-like Gaussians: lines of needles 0.6 mm thick (about 0.1 px at 64 px from the ring:
    far below a pixel, where the mip filter changes the coverage most), random opacities."""
    g = torch.Generator().manual_seed(seed)
    t = torch.linspace(-0.4, 0.4, per)
    means, quats = [], []
    for k in range(n_spokes):
        a = torch.tensor(3.1416 * k / n_spokes)
        d = torch.stack([torch.cos(a), torch.sin(a), torch.tensor(0.0)])
        means.append(t[:, None] * d + torch.tensor([0.0, 1.0, 0.0]))
        half = a / 2  # the needle's long local x turned onto d (about z)
        quats.append(torch.stack([torch.cos(half), torch.tensor(0.0), torch.tensor(0.0), torch.sin(half)]).repeat(per, 1))
    means, quats = torch.cat(means), torch.cat(quats)
    n = len(means)
    ls = torch.log(torch.tensor([0.012, 0.0006, 0.0006])).repeat(n, 1)
    return Gaussians(means, quats, ls, torch.randn(n, generator=g) + 2.0, torch.zeros(n, 1, 3))


def _cam(az=0, size=64):
    return ring_camera(az, orbit_centre=(0, 1, 0), size=size, focal=FOCAL * size / 64)


def test_fit_composites_through_the_mip_filter_as_the_render():
    # what the relight fit composites (prepare + composite_features) must be what render_relit draws
    # (coverage and composited colour), with the filter on all Gaussians, on a mask of them, and off
    g = _spokes()
    n = len(g)
    gen = torch.Generator().manual_seed(1)
    alb = torch.rand(n, 3, generator=gen) * 0.8
    nrm = torch.nn.functional.normalize(torch.randn(n, 3, generator=gen), dim=-1)
    cam = _cam(10)
    mask = torch.arange(n) % 2 == 0
    alphas = {}
    for aa in (True, mask, False):
        out = render_relit(g, alb, nrm, cam, Light(), None, antialiased=aa, reflectance=True)
        (R,), alpha = composite_features(prepare(g, cam, aa), [alb])
        assert float(alpha.max()) > 0.05
        torch.testing.assert_close(out["alpha"], alpha, atol=2e-4, rtol=1e-3)
        torch.testing.assert_close(out["reflectance"], R, atol=2e-4, rtol=1e-3)
        alphas[aa is True, aa is False] = alpha
    # sub-pixel needles: the filter takes most of their coverage away (so the check above can fail)
    assert float(alphas[True, False].sum()) < 0.5 * float(alphas[False, True].sum())
    with pytest.raises(ValueError, match="antialiased mask"):
        prepare(g, cam, mask[:-1])


def test_fit_of_antialiased_gaussians_recovers_their_albedo(monkeypatch):
    # passes rendered from needles drawn with the filter: fitted through it the albedo comes back;
    # fitted without it (the old fit) the coverage is too large and the albedo comes out dark
    import splatting.relight.fit as fit
    from splatting.relight.fit import RelightFitConfig, fit_relight

    g = _spokes(seed=3)
    n = len(g)
    true_alb = torch.where(g.means[:, :1] > 0, torch.tensor([0.7, 0.5, 0.2]), torch.tensor([0.2, 0.4, 0.6]))
    views, targets = pass_views(g, true_alb, torch.tensor([0.0, 0.0, -1.0]).repeat(n, 1), torch.full((n, 3), 0.1),
                                antialiased=True)
    monkeypatch.setattr(fit, "load_pass_targets", lambda v, s: targets)
    cfg = RelightFitConfig(iterations=150, holdout=(2,), progress=False, shading_loss=0.0)
    with_aa, m = fit_relight(g, views, cfg, antialiased=True)
    without, _ = fit_relight(g, views, cfg, antialiased=False)
    inner = g.means[:, :2].sub(torch.tensor([0.0, 1.0])).norm(dim=-1).lt(0.3)  # not the spokes' ends
    assert m["antialiased"] is True and m["heldout_albedo_psnr"] > 35
    err_aa = (with_aa["albedo"][inner] - true_alb[inner]).abs().mean()
    err_plain = (without["albedo"][inner] - true_alb[inner]).abs().mean()
    assert float(err_aa) < 0.03
    assert float(err_plain) > 3 * float(err_aa)


def test_shadow_maps_draw_antialiased_gaussians_with_the_filter():
    # a screen of 0.5 mm dust 1 map pixel apart 0.3 m over a plane: drawn plainly each speck grows
    # to a 0.3 px^2 blob at full opacity and the screen reads as a roof (the plane in shadow);
    # with the filter the specks keep their few-percent coverage and the sun passes
    from splatting.relight.shadow import sky_visibility, sun_visibility

    plane, dust = level_grid(0.5, 21, 0.0), level_grid(0.3, 101, 0.3)
    n = len(plane) + len(dust)
    g = axis_splats(torch.cat([plane, dust]), torch.cat([torch.tensor([[0.03, 0.002, 0.03]]).expand(len(plane), 3),
                                                         torch.full((len(dust), 3), 0.0005)]), 5.0)
    under = (plane[:, 0].abs() < 0.2) & (plane[:, 2].abs() < 0.2)
    light = Light(sun_direction=(0.0, 1.0, 0.0))
    plain = sun_visibility(g, light)[: len(plane)][under]
    aa = sun_visibility(g, light, antialiased=True)[: len(plane)][under]
    masked = sun_visibility(g, light, antialiased=torch.arange(n) >= len(plane))[: len(plane)][under]
    assert float(plain.max()) < 0.2
    assert float(aa.min()) > 0.9 and float(masked.min()) > 0.9
    up = torch.tensor([0.0, 1.0, 0.0]).repeat(n, 1)
    sky_plain = sky_visibility(g, up, directions=8)[: len(plane)][under].mean()
    sky_aa = sky_visibility(g, up, directions=8, antialiased=True)[: len(plane)][under].mean()
    assert float(sky_aa) > float(sky_plain) + 0.2


def _run_fit(*args):
    return subprocess.run([sys.executable, "-m", "splatting", "relight-fit", *args], capture_output=True, text=True)


def test_relight_fit_bike_bad_input(tmp_path):
    r = _run_fit("--bike", str(tmp_path / "nope"))
    assert r.returncode == 2 and "bike folder not found" in r.stderr and r.stderr.count("\n") == 1
    r = _run_fit("--bike", str(tmp_path), "--relit-loss", "-1")
    assert r.returncode == 2 and "--relit-loss must be >= 0" in r.stderr and r.stderr.count("\n") == 1
    r = _run_fit("--bike", str(tmp_path), "--views", str(tmp_path))
    assert r.returncode == 2 and "not allowed with" in r.stderr and r.stderr.count("\n") == 1
    d = make_bike(tmp_path)
    r = _run_fit("--bike", d)  # trained parts, but no views folders to fit on
    assert r.returncode == 2 and "has no views folder" in r.stderr and r.stderr.count("\n") == 1
    assert not any(f.endswith(".relight.npz") for f in os.listdir(os.path.join(d, "gaussians")))


def test_relight_fit_reads_the_mip_filter_from_the_parts(tmp_path):
    from cyclist_formats.errors import UserError
    from splatting.relight.fit import bike_parts, trained_antialiased

    d = make_bike(tmp_path)
    for p in ("frame", "steering", "crank"):
        os.makedirs(os.path.join(d, "views", p))
        with open(os.path.join(d, "views", p, "cameras.json"), "w") as f:
            f.write("{}")
    gp = os.path.join(d, "gaussians")
    assert not trained_antialiased(os.path.join(gp, "frame.ply"))  # no metrics: plain
    for p in ("frame", "steering"):
        with open(os.path.join(gp, p + ".json"), "w") as f:
            json.dump({"config": {"antialiased": True}}, f)
    assert trained_antialiased(os.path.join(gp, "frame.ply"))
    with pytest.raises(UserError, match="with and without antialiasing"):
        bike_parts(d)  # crank plain, the others filtered: refused before any fit
    with open(os.path.join(gp, "crank.json"), "w") as f:
        json.dump({"config": {"antialiased": True}}, f)
    assert bike_parts(d) == ["frame", "steering", "crank"]


def test_relight_fit_defaults_differ_for_a_bike_and_a_views_folder(tmp_path, monkeypatch):
    # --bike: a bike's parts (BIKE_ITERATIONS steps, the relit loss on); --views: one part or an
    # avatar (the config's defaults: the relit loss shades with the bike's roughness, so off)
    import argparse

    import splatting.relight.command as command
    import splatting.relight.fit as fit

    seen = []
    monkeypatch.setattr(fit, "fit_bike", lambda d, cfg: seen.append(cfg) or {})
    monkeypatch.setattr(fit, "fit_file", lambda v, p, cfg: seen.append(cfg) or {"path": "x", "wall_s": 0})
    p = argparse.ArgumentParser()
    command.add_arguments(p)
    for argv in (["--bike", str(tmp_path)], ["--views", str(tmp_path)], ["--bike", str(tmp_path), "--iterations", "7",
                                                                          "--relit-loss", "0", "--no-view-normals"],
                 ["--views", str(tmp_path), "--view-normals"]):
        assert command.run(p.parse_args(argv)) == 0
    bike, views, given, views_vn = seen
    assert (bike.iterations, bike.relit_loss) == (fit.BIKE_ITERATIONS, fit.BIKE_RELIT_LOSS) == (150, 3.0)
    assert bike.view_normals is fit.BIKE_VIEW_NORMALS is True
    assert (views.iterations, views.relit_loss, views.view_normals) == (fit.RelightFitConfig().iterations, 0.0, False)
    assert (given.iterations, given.relit_loss, given.view_normals) == (7, 0.0, False)
    assert views_vn.view_normals is True

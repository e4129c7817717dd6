"""Per-part trainer: fits a known scene, rejects NaN steps, densify rules and strategies, bad input,
the command line derived from the config."""
import argparse
import json
import math
import os
import subprocess
import sys

import pytest
import torch

from splatting.training import command
from splatting.training.strategy import STRATEGIES, DensifyConfig, DensifyStrategy, FixedStrategy, Strategy, make_strategy
from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import updated
from splatting.gaussians.container import Gaussians, read_ply
from splatting.gaussians.sh import rgb_to_sh0
from splatting.training.trainer import (TrainConfig, default_out, init_gaussians, split_views, train, train_views)
from splatting.training.views import load_views, render_ring_views, write_views

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SIZE = 96  # the 512 px ring scaled down: 1 px = 3 cm at 12 m


def bike_like_scene(seed=0, n=40):
    """A part-like object: coloured tubes (a triangle frame) and a dark wheel ring, ~1.6 m long."""
    g = torch.Generator().manual_seed(seed)
    segs = [((-0.6, 0.35, 0.0), (0.0, 0.35, 0.0)), ((0.0, 0.35, 0.0), (0.4, 0.9, 0.0)),
            ((-0.1, 0.95, 0.0), (0.4, 0.9, 0.0)), ((-0.6, 0.35, 0.0), (-0.1, 0.95, 0.0))]
    pts, cols = [], []
    for k, (a, b) in enumerate(segs):
        t = torch.rand(n, 1, generator=g)
        pts.append(torch.tensor(a) * (1 - t) + torch.tensor(b) * t + 0.01 * torch.randn(n, 3, generator=g))
        cols.append(torch.tensor([0.8, 0.15 + 0.2 * k, 0.1]).repeat(n, 1))
    th = torch.rand(3 * n, generator=g) * 2 * math.pi
    pts.append(torch.stack([-0.6 + 0.33 * th.cos(), 0.35 + 0.33 * th.sin(), 0.02 * torch.randn(3 * n, generator=g)], 1))
    cols.append(torch.tensor([0.1, 0.1, 0.3]).repeat(3 * n, 1))
    means, cols = torch.cat(pts), torch.cat(cols)
    q = torch.randn(len(means), 4, generator=g)
    return Gaussians(means, q / q.norm(dim=-1, keepdim=True),
                     torch.log(0.01 + 0.015 * torch.rand(len(means), 3, generator=g)),
                     torch.full((len(means),), 2.0), rgb_to_sh0(cols)[:, None])


def render_views(scene, size=SIZE, centre=(0.0, 0.65, 0.0)):
    """36 ring views of `scene` as straight-alpha RGBA (V, H, W, 4)."""
    return render_ring_views(scene, size, centre)


def make_views(folder, seed=0, points=True):
    scene = bike_like_scene(seed)
    cams, imgs = render_views(scene)
    g = torch.Generator().manual_seed(seed + 1)
    pts = scene.means[torch.randint(len(scene), (1500,), generator=g)] + 0.01 * torch.randn(1500, 3, generator=g)
    write_views(folder, cams, imgs, pts if points else None, (0.0, 0.65, 0.0))
    return folder


def fast_config(**kw):
    # threads=1: module fixtures run before conftest's per-test thread limit
    densify = {"start": 100, "stop": 300, "max_gaussians": 4000, **kw.pop("densify", {})}
    return updated(TrainConfig(**{"iterations": 400, "progress": False, "threads": 1, **kw}), densify=densify)


@pytest.fixture(scope="module")
def views_dir(tmp_path_factory):
    return make_views(str(tmp_path_factory.mktemp("bike") / "views" / "frame"))


@pytest.fixture(scope="module")
def trained(views_dir, tmp_path_factory):
    out = str(tmp_path_factory.mktemp("g") / "frame.ply")
    metrics = train(views_dir, out, fast_config())
    return out, metrics


def white_psnr_of_empty(views, idx):
    """PSNR of predicting plain white (an empty model) on the held-out views: the floor to beat."""
    vals = []
    for i in idx:
        im = views.images[i]
        gt = im[..., :3] * im[..., 3:] + 1 - im[..., 3:]
        vals.append(10 * math.log10(1 / float(((gt - 1) ** 2).mean())))
    return sum(vals) / len(vals)


def test_fits_known_scene(trained, views_dir):
    out, m = trained
    views = load_views(views_dir)
    _, hold = split_views(views, (3, 12, 21, 30))
    floor = white_psnr_of_empty(views, hold)
    # Measured (seeds 0, 1): 44.9 / 45.5 dB whole image, 39.6 / 40.2 dB in the object's box, after
    # 400 iterations. The scene is made of Gaussians, so it is exactly representable; the empty
    # (all-white) model scores `floor` = 17.7 dB. 36 dB whole / 31 dB box (~3% RMS error on the
    # object) leaves ~9 dB for other seeds, thread counts and devices, and still fails a trainer
    # that gets the colours or the 1 px-wide tubes wrong.
    assert m["psnr"] > 36.0 and m["psnr"] > floor + 15, (m["psnr"], floor)
    assert m["psnr_crop"] > 31.0
    assert m["ssim"] > 0.98
    assert m["gaussians"] <= 4000
    assert m["rejected_steps"] == 0
    saved = json.load(open(os.path.splitext(out)[0] + ".json"))
    for k in ("psnr", "ssim", "gaussians", "wall_s", "iterations", "sh_degree", "max_gaussians", "psnr_history"):
        assert k in saved
    assert saved["holdout"] == ["camera0003", "camera0012", "camera0021", "camera0030"]
    assert len(read_ply(out)) == m["gaussians"]


def test_nan_view_steps_are_rejected_and_training_continues(views_dir):
    views = load_views(views_dir)
    y, x = torch.nonzero(views.images[7, ..., 3] > 0.5)[0]
    views.images[7, y, x, 0] = float("nan")  # one training view (on the object) now gives a NaN loss
    g, m = train_views(views, fast_config())
    # 400 iterations over 32 training views: view 7 comes up 12 or 13 times (epoch shuffles)
    assert 12 <= m["rejected_steps"] <= 13
    assert all(torch.isfinite(getattr(g, f)).all() for f in ("means", "quats", "log_scales", "opacity_logits", "sh"))
    assert m["psnr"] > 34.0


def test_rejected_steps_leave_parameters_untouched(views_dir):
    views = load_views(views_dir)
    views.images[..., 0] = float("nan")  # every step is NaN: nothing may move
    cfg = fast_config(iterations=30, densify={"hull_prune": False})
    g, m = train_views(views, cfg)
    assert m["rejected_steps"] == 30
    gen = torch.Generator().manual_seed(cfg.seed)
    g0 = init_gaussians(views, cfg, gen)
    assert torch.equal(g.means, g0.means) and torch.equal(g.opacity_logits, g0.opacity_logits)
    assert torch.equal(g.log_scales, g0.log_scales) and torch.equal(g.sh, g0.sh)


def test_early_stop_and_time_budget(views_dir):
    views = load_views(views_dir)
    # a gain of 100 dB is never reached: stop at the first evaluation after densification ends
    cfg = fast_config(iterations=2000, eval_every=50, patience=1, min_delta_db=100.0, densify={"stop": 100})
    _, m = train_views(views, cfg)
    assert m["stopped"] == "early" and m["iterations"] == 150
    assert [h[0] for h in m["psnr_history"]] == [50, 100, 150]
    _, m = train_views(views, fast_config(iterations=10 ** 6, time_budget_s=1.0))
    assert m["stopped"] == "time_budget" and 0 < m["iterations"] < 10 ** 6 and m["wall_s"] < 5


def test_random_init_without_points(tmp_path):
    d = make_views(str(tmp_path / "views" / "steering"), seed=3, points=False)
    views = load_views(d)
    assert views.points is None
    g0 = init_gaussians(views, fast_config(), torch.Generator().manual_seed(0))
    # carved from the silhouettes: every initial centre lies near the true object (within its box + 10 cm)
    lo, hi = bike_like_scene(3).means.min(0).values - 0.1, bike_like_scene(3).means.max(0).values + 0.1
    assert len(g0) > 100 and ((g0.means >= lo) & (g0.means <= hi)).all()


def test_default_out_path():
    assert default_out("/o/bikes/b1/views/crank") == "/o/bikes/b1/gaussians/crank.ply"
    with pytest.raises(UserError):
        default_out("/o/somewhere/crank")


# -- densification rules -------------------------------------------------------------------------

def _params(n, log_scale, opac):
    p = {"means": torch.zeros(n, 3), "quats": torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
         "log_scales": torch.full((n, 3), 0.0) + torch.tensor(log_scale)[:, None],
         "opacity_logits": torch.logit(torch.tensor(opac)), "sh0": torch.zeros(n, 1, 3), "shN": torch.zeros(n, 0, 3)}
    p = {k: torch.nn.Parameter(v.clone()) for k, v in p.items()}
    opt = torch.optim.Adam([{"params": [v], "name": k} for k, v in p.items()], lr=1e-3)
    for v in p.values():
        v.grad = torch.ones_like(v)
    opt.step()  # creates Adam state, which must follow the set
    return p, opt


def test_clone_split_prune_follow_object_extent():
    extent = 2.0  # percent_dense 0.01 -> clone at or below 2 cm, split above
    # 0: small, high gradient -> clone; 1: large, high gradient -> split; 2: transparent -> prune;
    # 3: low gradient -> untouched
    p, opt = _params(4, [math.log(0.01), math.log(0.05), math.log(0.01), math.log(0.01)], [0.5, 0.5, 0.001, 0.5])
    d = DensifyStrategy(DensifyConfig(start=1, stop=100, every=2), extent)
    grad = torch.tensor([[1e-3, 0.0], [1e-3, 0.0], [1e-3, 0.0], [1e-6, 0.0]])  # pixels at W = H = 2 -> x1 NDC
    d.accumulate(grad, torch.ones(4, dtype=torch.long), 2, 2)
    assert d.step(1, p, opt)  # 1 % 2 == 2 // 2: a densify step
    s = torch.exp(p["log_scales"].detach()).max(-1).values.sort().values
    # kept: 0 and 3; clone of 0; two children of 1 with scale 0.05 / (0.8 * 2) (Adam's one warm-up
    # step moved the log-scales by 1e-3)
    assert len(p["means"]) == 5
    assert torch.allclose(s, torch.tensor([0.01, 0.01, 0.01, 0.05 / 1.6, 0.05 / 1.6]), rtol=3e-3)
    assert (torch.sigmoid(p["opacity_logits"]) > 0.1).all()
    for group in opt.param_groups:
        par = group["params"][0]
        assert par is p[group["name"]]
        assert opt.state[par]["exp_avg"].shape == par.shape
    assert d.stats["cloned"] == 1 and d.stats["split"] == 1 and d.stats["pruned"] == 1


def test_budget_is_hard():
    p, opt = _params(10, [math.log(0.01)] * 10, [0.5] * 10)
    d = DensifyStrategy(DensifyConfig(start=1, stop=100, every=2, max_gaussians=13), extent=2.0)
    d.accumulate(torch.arange(1, 11).float()[:, None].repeat(1, 2) * 1e-3, torch.ones(10, dtype=torch.long), 2, 2)
    d.step(1, p, opt)
    assert len(p["means"]) == 13 and d.stats["budget_capped"] == 7


def test_size_threshold_is_relative_to_object_not_cameras():
    # the same 5 cm Gaussian is split for a 2 m object and cloned for a 12 m "scene"
    for extent, want in ((2.0, "split"), (12.0, "cloned")):
        p, opt = _params(1, [math.log(0.05)], [0.5])
        d = DensifyStrategy(DensifyConfig(start=1, stop=100, every=2), extent)
        d.accumulate(torch.tensor([[1e-3, 0.0]]), torch.ones(1, dtype=torch.long), 2, 2)
        d.step(1, p, opt)
        assert d.stats[want] == 1


# -- bad input -----------------------------------------------------------------------------------

def test_bad_views_give_user_errors_and_no_output(tmp_path, views_dir):
    out = tmp_path / "g" / "x.ply"
    with pytest.raises(UserError, match="not found"):
        train(str(tmp_path / "missing"), str(out), fast_config())
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "cameras.json").write_text('{"orbit_centre": [0, 0, 0]}')
    with pytest.raises(UserError, match="zero views"):
        train(str(empty), str(out), fast_config())
    assert not out.exists() and not (tmp_path / "g" / "x.json").exists()


def _run_cli(*args):
    return subprocess.run([sys.executable, "-m", "splatting", "train", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=120,
                          env={**os.environ, "OMP_NUM_THREADS": "1"})


def test_cli_bad_input_one_line_exit_2(tmp_path):
    bad = tmp_path / "bikes" / "b" / "views" / "frame"
    bad.mkdir(parents=True)
    (bad / "cameras.json").write_text("{not json")
    r = _run_cli("--views", str(bad))
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and "cameras.json" in r.stderr
    assert not (tmp_path / "bikes" / "b" / "gaussians").exists()


def test_cli_trains_to_default_out(tmp_path):
    d = make_views(str(tmp_path / "bikes" / "b7" / "views" / "crank"))
    r = _run_cli("--views", d, "--iterations", "60", "--max-gaussians", "2000", "--threads", "1", "--quiet")
    assert r.returncode == 0, r.stderr
    ply = tmp_path / "bikes" / "b7" / "gaussians" / "crank.ply"
    m = json.loads((tmp_path / "bikes" / "b7" / "gaussians" / "crank.json").read_text())
    assert ply.exists() and m["iterations"] == 60 and m["part"] == "crank" and m["gaussians"] <= 2000


# ------------------------------------------------ strategies from the config, CLI from the config

def parse(*argv):
    p = argparse.ArgumentParser()
    command.add_arguments(p)
    return p.parse_args(["--views", "v", *argv])


def test_cli_defaults_are_the_config_defaults():
    cfg = command.config_from_args(parse())
    d = TrainConfig()
    for name in TrainConfig.model_fields:
        if name not in ("progress", "densify"):
            assert getattr(cfg, name) == getattr(d, name), name
    assert cfg.densify == d.densify


def test_cli_sets_nested_and_tuple_fields():
    cfg = command.config_from_args(parse("--max-gaussians", "123", "--holdout", "1,2", "--strategy", "fixed"))
    assert cfg.densify.max_gaussians == 123 and cfg.holdout == (1, 2) and cfg.strategy == "fixed"
    with pytest.raises(UserError, match="max-gaussians"):
        command.config_from_args(parse("--max-gaussians", "0"))


def test_cli_antialiased_is_an_on_off_flag():
    # a bool field is --x / --no-x, not type=bool (which reads "False" as true)
    assert command.config_from_args(parse("--antialiased")).antialiased is True
    assert command.config_from_args(parse("--no-antialiased")).antialiased is False
    with pytest.raises(SystemExit):
        parse("--antialiased", "False")


def test_antialiased_training_fits_and_says_so(views_dir, tmp_path):
    """antialiased=True trains through the compensated opacities and records it in PART.json
    (renderers read it there); the fit reaches the same bar as the plain one, shorter run."""
    m = train(views_dir, str(tmp_path / "frame.ply"), fast_config(antialiased=True))
    assert m["antialiased"] is True and m["config"]["antialiased"] is True
    assert m["psnr_crop"] > 28.0, m["psnr_crop"]


def test_strategies_implement_the_interface():
    assert set(STRATEGIES) == {"default", "fixed"}
    for cls in STRATEGIES.values():
        assert issubclass(cls, Strategy)
    with pytest.raises(UserError, match="unknown densification strategy"):
        make_strategy("nope", TrainConfig().densify, 1.0)


def test_fixed_strategy_keeps_the_set_and_default_grows_it(views_dir):
    views = load_views(views_dir)
    counts = {}
    for name in ("fixed", "default"):
        cfg = fast_config(iterations=160, strategy=name,
                          densify={"start": 20, "stop": 150, "min_opacity": 0.0, "hull_prune": False})
        g, m = train_views(views, cfg)
        counts[name] = len(g)
        if name == "fixed":
            assert m["densify"] == {}
    assert isinstance(make_strategy("fixed", TrainConfig().densify, 1.0), FixedStrategy)
    assert isinstance(make_strategy("default", TrainConfig().densify, 1.0), DensifyStrategy)
    assert counts["default"] > counts["fixed"], counts

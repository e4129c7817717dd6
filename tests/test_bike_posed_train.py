"""splatting/bike/posed_train.py: fine-tuning the parts through the 8-DoF pose recovers a bike seen
only in posed renders (a synthetic bike draws its own targets; no Blender), and bad input is refused."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from PIL import Image

from cyclist_formats import bike_folder, ring
from cyclist_formats.errors import UserError
from splatting.bike.model import BikeModel
from splatting.bike.posed_train import HELD_OUT, PosedTrainConfig, done_with, fine_tune, training_poses
from splatting.gaussians.container import Gaussians, write_ply
from splatting.raster.camera import from_numpy
from splatting.raster.sparse import render_gaussians

from helpers import make_bike

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SIZE = 64


def _save_rgba(out, path):
    a = out["alpha"].clamp(0, 1)
    straight = (out["rgb"] / a.clamp_min(1e-6)[..., None]).clamp(0, 1)
    rgba = torch.cat([straight, a[..., None]], -1).numpy()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    Image.fromarray((rgba * 255).round().astype(np.uint8), "RGBA").save(path)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A synthetic bike whose colours were changed (the 'rest-trained' start) and renders of the
    original (the targets) at rest on a ring and at the training poses."""
    root = tmp_path_factory.mktemp("posed")
    d = make_bike(root, sh_degree=0, n=300)
    target = BikeModel.load(d)
    for i, p in enumerate(target.part_names):  # the start: every part's colour shifted
        a, e = target.ranges[i]
        c = target.canonical
        g = Gaussians(c.means[a:e], c.quats[a:e], c.log_scales[a:e], c.opacity_logits[a:e], c.sh[a:e] + 0.25)
        write_ply(g, os.path.join(d, "gaussians", p + ".ply"))
    cams = ring.ring([0.0, 0.5, 0.0], size=SIZE, focal=ring.focal_for(SIZE) * 2)
    whole = os.path.join(d, "views", "whole")
    os.makedirs(whole)
    bike_folder.write_views_meta(whole, cams)
    cam_file = os.path.join(whole, "cameras.json")
    rest_g = target.pose(torch.zeros(8, dtype=torch.float64)).gaussians
    for name in sorted(k for k in cams if k.startswith("camera")):
        K, R, T = ring.camera_entry(cam_file, name)
        with torch.no_grad():
            _save_rgba(render_gaussians(rest_g, from_numpy(K, R, T)), os.path.join(whole, "rgba", name, "0000.png"))
    poses, cam_ids = training_poses(12)
    poses[:, 5:] = 0  # keep the bike in the small frame
    jobs = []
    for k, (p, c) in enumerate(zip(poses, cam_ids)):
        name = f"camera{int(c):04d}"
        K, R, T = ring.camera_entry(cam_file, name)
        out = os.path.join(d, "views", "posed", f"posed_{k:03d}.png")
        with torch.no_grad():
            _save_rgba(render_gaussians(target.pose(torch.tensor(p, dtype=torch.float64)).gaussians, from_numpy(K, R, T)), out)
        jobs.append({"pose": [float(v) for v in p], "camera": f"{cam_file}:{name}", "out": out})
    return d, jobs


def test_from_rest_starts_from_the_rest_parts_and_never_writes_them(scene, tmp_path):
    """--from-rest (the library's posed task): the train tasks left gaussians/<part>_rest.ply and no
    <part>.ply; the fine-tune reads those, writes <part>.ply, and never touches a _rest file, also
    when a killed run left a stale <part>.ply behind (it is overwritten, never copied onto the rest)."""
    import shutil

    from splatting.bike.posed_train import train_bike_posed

    d = str(tmp_path / "bike")
    shutil.copytree(scene[0], d)
    g = os.path.join(d, "gaussians")
    for f in os.listdir(g):
        base, ext = os.path.splitext(f)
        os.rename(os.path.join(g, f), os.path.join(g, base + "_rest" + ext))
    rest = {f: open(os.path.join(g, f), "rb").read() for f in os.listdir(g)}
    cfg = PosedTrainConfig(poses=12, iterations=3, progress=False)  # the fixture's 12 posed views: no Blender
    train_bike_posed(d, cfg, log=lambda s: None, from_rest=True)
    parts = ("frame", "steering", "crank")
    first = {p: open(os.path.join(g, p + ".ply"), "rb").read() for p in parts}
    assert all(first[p] != rest[p + "_rest.ply"] for p in parts)  # fine-tuned from the rest parts
    shutil.copyfile(os.path.join(g, "crank.ply"), os.path.join(g, "frame.ply"))  # a killed run's leftover
    os.remove(os.path.join(g, "posed_train.json"))
    train_bike_posed(d, cfg, log=lambda s: None, from_rest=True)
    assert {f: open(os.path.join(g, f), "rb").read() for f in rest} == rest
    assert {p: open(os.path.join(g, p + ".ply"), "rb").read() for p in parts} == first
    assert BikeModel.load(d).part_names == list(parts)  # the final bike loads from <part>.ply


def test_fine_tuning_through_the_pose_recovers_the_posed_bike(scene):
    d, jobs = scene
    start = BikeModel.load(d)
    cfg = PosedTrainConfig(poses=len(jobs), iterations=150, lr_sh0=2e-2, progress=False)
    parts, m = fine_tune(start, os.path.join(d, "views", "whole"), jobs, cfg)
    # the held-out poses (never trained on) get much closer to the target's renders
    assert m["held_out_poses"] == HELD_OUT
    assert m["held_out_box_psnr_after"] > m["held_out_box_psnr_before"] + 5, m
    # the fine-tuner's own posing (per-part rigid transforms of the canonical parameters) puts every
    # part where BikeModel.pose drew the targets: the silhouettes agree before any step
    assert m["held_out_iou_before"] > 0.97 and m["held_out_iou_after"] > 0.97, m
    assert list(parts) == start.part_names
    for i, p in enumerate(start.part_names):  # same Gaussians, same order and count per part
        a, e = start.ranges[i]
        assert len(parts[p]) == e - a


@pytest.mark.parametrize("tail", [0, 8])
def test_lr_decay_follows_its_schedule(scene, monkeypatch, tail):
    """--lr-decay d: step k (1-based) of N runs every group at lr0 * d ** ((k - 1) / N): the first at
    the start rates, the rates falling exponentially; 1.0 keeps them constant. With --lr-tail T the
    rates stay at lr0 until the last T steps and fall as d ** (share of the tail done). Checked on
    the rates Adam actually steps with (densification on, which replaces the groups' tensors)."""
    d, jobs = scene
    seen = []
    step = torch.optim.Adam.step

    def spy(self, *a, **k):
        seen.append({g["name"]: g["lr"] for g in self.param_groups})
        return step(self, *a, **k)

    monkeypatch.setattr(torch.optim.Adam, "step", spy)
    n, decay = 20, 0.01
    cfg = PosedTrainConfig(poses=len(jobs), iterations=n, lr_decay=decay, lr_tail=tail, densify=True, progress=False)
    _, m = fine_tune(BikeModel.load(d), os.path.join(d, "views", "whole"), jobs, cfg)
    assert m["config"]["lr_decay"] == decay
    parts = 3
    assert len(seen) == n * parts  # one Adam per part, every step accepted
    first = seen[:parts]
    for k in range(n):
        for i in range(parts):
            got, lr0 = seen[k * parts + i], first[i]
            for name in lr0:
                want = decay ** (k / n) if not tail else decay ** (max(0, k - (n - tail)) / tail)
                assert got[name] == pytest.approx(lr0[name] * want, rel=1e-9), (k, name)
    if tail:  # constant up to the tail, then falling
        assert seen[(n - tail) * parts]["sh0"] == first[0]["sh0"] > seen[(n - tail + 1) * parts]["sh0"]
    assert seen[-1]["sh0"] < 0.02 * seen[0]["sh0"]
    seen.clear()
    fine_tune(BikeModel.load(d), os.path.join(d, "views", "whole"), jobs,
              PosedTrainConfig(poses=len(jobs), iterations=5, progress=False))
    assert all(s == seen[i % parts] for i, s in enumerate(seen)) and len(seen) == 5 * parts


def test_done_with_reads_the_config(tmp_path):
    d = make_bike(tmp_path, sh_degree=0)
    assert done_with(d, PosedTrainConfig()) is None
    cfg = PosedTrainConfig()
    c = cfg.model_dump()
    c.pop("progress")
    with open(os.path.join(d, "gaussians", "posed_train.json"), "w") as f:
        json.dump({"config": c}, f)
    assert done_with(d, PosedTrainConfig(progress=False)) is not None
    assert done_with(d, PosedTrainConfig(iterations=cfg.iterations + 1)) is None
    assert done_with(d, PosedTrainConfig(lr_decay=0.1)) is None
    # a record from before --lr-decay (no key) ran at constant rates
    c.pop("lr_decay")
    with open(os.path.join(d, "gaussians", "posed_train.json"), "w") as f:
        json.dump({"config": c}, f)
    assert done_with(d, PosedTrainConfig(lr_decay=1.0)) is not None
    assert done_with(d, PosedTrainConfig(lr_decay=0.5)) is None
    # a record from before --eps2d (no key) rendered with rasterize's 0.3
    c.pop("eps2d")
    with open(os.path.join(d, "gaussians", "posed_train.json"), "w") as f:
        json.dump({"config": c}, f)
    assert done_with(d, PosedTrainConfig(eps2d=0.3)) is not None
    assert done_with(d, PosedTrainConfig(eps2d=0.173)) is None
    # a part retrained after the fine-tune (its file newer than posed_train.json): fine-tune again
    t = os.path.getmtime(os.path.join(d, "gaussians", "posed_train.json"))
    os.utime(os.path.join(d, "gaussians", "steering.ply"), (t + 5, t + 5))
    assert done_with(d, PosedTrainConfig()) is None


@pytest.mark.parametrize("have,want", [(1, 2), (2, 1), (3, 2), (1, 0)])
def test_parts_of_another_sh_degree_are_refused(tmp_path, have, want):
    d = make_bike(tmp_path, sh_degree=have)
    with pytest.raises(UserError, match="SH degree 0"):
        fine_tune(BikeModel.load(d), str(tmp_path), [], PosedTrainConfig(sh_degree=want, progress=False))


def test_a_fine_tuned_bike_continues_from_its_own_sh(scene, tmp_path):
    """Parts of the fine-tune's own --sh-degree (an earlier fine-tune's output) are continued:
    every coefficient starts where it was, so the held-out score before the steps is the
    continued bike's as BikeModel draws it."""
    d, jobs = scene
    start = BikeModel.load(d)
    cfg = PosedTrainConfig(poses=len(jobs), iterations=30, sh_degree=2, lr_shN=2e-2, progress=False)
    parts, m = fine_tune(start, os.path.join(d, "views", "whole"), jobs, cfg)
    b = str(tmp_path / "bike")
    import shutil
    shutil.copytree(d, b, ignore=shutil.ignore_patterns("posed_train.json", "*_rest.ply"))
    for p, g in parts.items():
        write_ply(g, os.path.join(b, "gaussians", p + ".ply"))
    again = BikeModel.load(b)
    assert again.sh_degree == 2 and again.canonical.sh[:, 1:].abs().max() > 0
    _, m2 = fine_tune(again, os.path.join(d, "views", "whole"), jobs, PosedTrainConfig(**dict(
        vars(cfg), iterations=1)))
    assert m2["held_out_box_psnr_before"] == m["held_out_box_psnr_after"], (m, m2)


def test_cli_refuses_bad_input(tmp_path):
    env = dict(os.environ, PYTHONPATH=ROOT)
    for args, msg in (([" --bike", str(tmp_path / "none")], "not found"),
                      (["--bike", str(tmp_path), "--poses", "2"], "poses"),
                      (["--bike", str(tmp_path), "--lr-decay", "0"], "lr-decay"),
                      (["--bike", str(tmp_path), "--lr-decay", "1.5"], "lr-decay"),
                      (["--bike", str(tmp_path), "--iterations", "10", "--lr-tail", "11"], "lr-tail"),
                      (["--bike", str(tmp_path), "--render-threads", "0"], "render-threads"),
                      (["--bike", str(tmp_path), "--eps2d", "0"], "eps2d"),
                      (["--bike", str(tmp_path), "--eps2d", "nan"], "eps2d"),
                      (["--bike", str(tmp_path), "--eps2d", "inf"], "eps2d"),
                      (["--bike", str(tmp_path)], "frame.ply")):
        r = subprocess.run([sys.executable, "-m", "splatting", "bike-posed-train"] + [a.strip() for a in args],
                           capture_output=True, text=True, env=env, cwd=ROOT)
        assert r.returncode == 2 and msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_reruns_start_from_the_rest_trained_parts(scene, tmp_path):
    """train_bike_posed keeps the rest-trained parts as <part>_rest.ply; a rerun (another config)
    starts from those, and a part retrained since the fine-tune becomes the new start."""
    import filecmp
    import shutil

    from splatting.bike.posed_train import train_bike_posed

    d = str(tmp_path / "bike")
    shutil.copytree(scene[0], d)
    g = os.path.join(d, "gaussians")
    orig = {p: open(os.path.join(g, p + ".ply"), "rb").read() for p in ("frame", "steering", "crank")}
    quiet = dict(poses=12, progress=False)  # the fixture rendered these 12 posed views: no Blender
    train_bike_posed(d, PosedTrainConfig(iterations=3, **quiet), log=lambda s: None)
    for p, data in orig.items():
        assert open(os.path.join(g, p + "_rest.ply"), "rb").read() == data
        assert open(os.path.join(g, p + ".ply"), "rb").read() != data  # fine-tuned
    assert done_with(d, PosedTrainConfig(iterations=3, **quiet)) is not None
    train_bike_posed(d, PosedTrainConfig(iterations=4, **quiet), log=lambda s: None)
    for p, data in orig.items():  # the second run started from the same rest copies
        assert open(os.path.join(g, p + "_rest.ply"), "rb").read() == data
    # steering retrained after the fine-tune: it is the new start, the others keep theirs
    shutil.copyfile(os.path.join(g, "frame_rest.ply"), os.path.join(g, "steering.ply"))
    t = os.path.getmtime(os.path.join(g, "posed_train.json"))
    os.utime(os.path.join(g, "steering.ply"), (t + 5, t + 5))
    assert done_with(d, PosedTrainConfig(iterations=4, **quiet)) is None
    train_bike_posed(d, PosedTrainConfig(iterations=4, **quiet), log=lambda s: None)
    assert filecmp.cmp(os.path.join(g, "steering_rest.ply"), os.path.join(g, "frame_rest.ply"), shallow=False)
    assert open(os.path.join(g, "crank_rest.ply"), "rb").read() == orig["crank"]


@pytest.mark.parametrize("degree", [1, 2])
def test_view_dependent_fine_tune_rotates_its_sh_as_bike_model_does(scene, degree):
    """With sh_degree=1 (2) the fine-tune adds band-1 (and band-2) SH and rotates it with each part;
    BikeModel.pose (its own SH rotation) must draw the fine-tuned parts exactly as the fine-tune
    scored them (a band rotated wrongly, or not at all, moves the held-out score)."""
    d, jobs = scene
    start = BikeModel.load(d)
    cfg = PosedTrainConfig(poses=len(jobs), iterations=40, lr_sh0=2e-2, lr_shN=2e-2, sh_degree=degree, progress=False)
    parts, m = fine_tune(start, os.path.join(d, "views", "whole"), jobs, cfg)
    assert all(g.sh.shape[1] == (degree + 1) ** 2 for g in parts.values())
    assert all(float(g.sh[:, (degree * degree):].abs().max()) > 1e-3 for g in parts.values())  # the top band was fitted
    ps = _held_out_psnr_of_bike_model(d, start, parts, jobs)
    assert abs(ps - m["held_out_box_psnr_after"]) < 0.05, (ps, m)


def _held_out_psnr_of_bike_model(d, start, parts, jobs):
    """Mean box PSNR of BikeModel (its own posing) drawing `parts` at the held-out posed renders."""
    from cyclist_formats import ring as ring_mod
    from splatting.training.metrics import box_psnr

    with open(os.path.join(d, "keypoints.json")) as f:
        model = BikeModel(parts, json.load(f), start.meta)
    ps = []
    for j in jobs[-HELD_OUT:]:
        path, _, name = j["camera"].rpartition(":")
        with torch.no_grad():
            o = render_gaussians(model.pose(torch.tensor(j["pose"], dtype=torch.float64)).gaussians,
                                 from_numpy(*ring_mod.camera_entry(path, name)))
        im = np.asarray(Image.open(j["out"]).convert("RGBA")).astype(np.float64) / 255
        gt = im[..., :3] * im[..., 3:]
        ps.append(box_psnr(o["rgb"].clamp(0, 1).double().numpy(), gt, o["alpha"].numpy() > 0.5, im[..., 3] > 0.5, pad=8))
    return float(np.mean(ps))


def test_more_poses_keep_the_first_ones():
    """--poses 100 starts with the 48 poses of --poses 48 (their renders are reused), and none of
    them is a ground-truth check pose (seed 0)."""
    from splatting.bike.pose import sample_poses

    p48, c48 = training_poses(48)
    p100, c100 = training_poses(100)
    assert len(p100) == len(c100) == 100
    np.testing.assert_array_equal(p100[:48], p48)
    np.testing.assert_array_equal(c100[:48], c48)
    assert len({tuple(p) for p in p100}) == 100
    checks, _ = sample_poses(12, 0)
    assert not {tuple(p) for p in checks} & {tuple(p) for p in p100}


FAKE_RENDER = """import json, sys
from PIL import Image
jobs = json.load(open(sys.argv[sys.argv.index("--batch") + 1]))
with open(sys.argv[0] + ".log", "a") as f:
    for j in jobs:
        Image.new("RGBA", (4, 4)).save(j["out"])
        f.write(j["out"] + "\\n")
with open(sys.argv[0] + ".args", "w") as f:
    f.write(" ".join(sys.argv[1:]))
"""


def test_renders_of_another_pose_are_rendered_again(tmp_path, monkeypatch):
    """A posed render is reused only while its pose, camera and settings are this job's: with more
    poses the old ones are kept and only the new ones rendered; a render whose pose changed (here:
    its poses.json entry edited) is rendered again."""
    from splatting.bike import posed_train

    d = tmp_path / "bike"
    whole = d / "views" / "whole"
    os.makedirs(whole)
    bike_folder.write_views_meta(str(whole), ring.ring([0.0, 0.5, 0.0], size=16, focal=ring.focal_for(16)))
    fake = tmp_path / "fake_render.py"
    fake.write_text(FAKE_RENDER)
    monkeypatch.setattr(posed_train, "RENDER_SCRIPT", str(fake))
    out = d / "views" / "posed"

    def rendered(cfg):
        log = tmp_path / "fake_render.py.log"
        if log.exists():
            log.unlink()
        posed_train.render_posed_views(str(d), str(out), cfg, log=lambda s: None)
        return sorted(os.path.basename(x) for x in log.read_text().split()) if log.exists() else []

    assert rendered(PosedTrainConfig(poses=6)) == [f"posed_{k:03d}.png" for k in range(6)]
    assert rendered(PosedTrainConfig(poses=6)) == []  # all reused
    assert rendered(PosedTrainConfig(poses=8)) == ["posed_006.png", "posed_007.png"]
    assert rendered(PosedTrainConfig(poses=6)) == [] and rendered(PosedTrainConfig(poses=8)) == []  # kept
    (out / "posed_009.png").write_bytes(b"")  # a file poses.json says nothing about is not trusted
    assert rendered(PosedTrainConfig(poses=10)) == ["posed_008.png", "posed_009.png"]
    meta = json.loads((out / "poses.json").read_text())
    meta["jobs"][3]["pose"][0] += 1.0  # posed_003.png was rendered at another pose
    (out / "poses.json").write_text(json.dumps(meta))
    assert rendered(PosedTrainConfig(poses=8)) == ["posed_003.png"]
    assert len(rendered(PosedTrainConfig(poses=8, samples=64))) == 8  # other settings: all again
    assert rendered(PosedTrainConfig(poses=10, samples=64)) == ["posed_008.png", "posed_009.png"]
    assert "--threads" not in (tmp_path / "fake_render.py.args").read_text().split()  # Blender's default
    posed_train.render_posed_views(str(d), str(out), PosedTrainConfig(poses=11, samples=64), log=lambda s: None, threads=1)
    assert "--threads 1" in (tmp_path / "fake_render.py.args").read_text()


def test_densify_grows_each_part_up_to_its_cap(scene):
    """--densify: each part runs the trainer's density control on its own slice of the composed
    render's screen-space gradients; no part passes densify_max, the parts grow, the record says
    so, and BikeModel draws the grown parts exactly as the fine-tune scored them."""
    d, jobs = scene
    start = BikeModel.load(d)
    sizes = {p: e - a for p, (a, e) in zip(start.part_names, start.ranges)}
    cap = max(sizes.values()) + 40
    cfg = PosedTrainConfig(poses=len(jobs), iterations=300, lr_sh0=2e-2, densify=True, densify_max=cap, progress=False)
    parts, m = fine_tune(start, os.path.join(d, "views", "whole"), jobs, cfg)
    n = {p: len(g) for p, g in parts.items()}
    assert m["gaussians"] == n and set(m["densify"]) == set(start.part_names), m
    assert all(k <= cap for k in n.values()), (n, cap)
    assert sum(n.values()) > sum(sizes.values()), (n, sizes)  # grown (the final prune drops only faint ones)
    assert sum(s["cloned"] + s["split"] for s in m["densify"].values()) > 0, m["densify"]
    # the colours are still recovered (the splits of this already-exact geometry cost some of the +5 dB)
    assert m["held_out_box_psnr_after"] > m["held_out_box_psnr_before"] + 3, m
    ps = _held_out_psnr_of_bike_model(d, start, parts, jobs)
    assert abs(ps - m["held_out_box_psnr_after"]) < 0.05, (ps, m)


def test_densify_off_keeps_old_records_and_on_is_another_config(tmp_path):
    """A posed_train.json written before --densify existed (no densify keys) is still the default
    config's; a densified fine-tune is not."""
    d = make_bike(tmp_path, sh_degree=0)
    c = PosedTrainConfig().model_dump()
    for k in ("progress", "densify", "densify_max"):
        c.pop(k)
    with open(os.path.join(d, "gaussians", "posed_train.json"), "w") as f:
        json.dump({"config": c}, f)
    assert done_with(d, PosedTrainConfig()) is not None
    assert done_with(d, PosedTrainConfig(densify=True)) is None


def test_cli_refuses_a_bad_densify_cap(tmp_path):
    env = dict(os.environ, PYTHONPATH=ROOT)
    d = make_bike(tmp_path, sh_degree=0)
    r = subprocess.run([sys.executable, "-m", "splatting", "bike-posed-train", "--bike", d, "--densify", "--densify-max", "0"],
                       capture_output=True, text=True, env=env, cwd=ROOT)
    assert r.returncode == 2 and "densify-max" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr



def test_the_fine_tune_renders_with_its_eps2d_and_the_bike_keeps_it(scene, tmp_path, monkeypatch):
    """--eps2d: the fine-tune draws (and scores) with it, posed_train.json records it, and
    BikeModel.load reads it back for the parts the fine-tune wrote."""
    import shutil

    from splatting.bike.posed_train import train_bike_posed

    d, jobs = scene
    scores = {}
    for eps in (0.3, 0.173):
        _, m = fine_tune(BikeModel.load(d), os.path.join(d, "views", "whole"), jobs,
                         PosedTrainConfig(poses=len(jobs), iterations=1, eps2d=eps, progress=False))
        assert m["eps2d"] == eps and m["config"]["eps2d"] == eps
        scores[eps] = m["held_out_box_psnr_before"]
    assert scores[0.3] != scores[0.173]  # the held-out renders used it
    b = str(tmp_path / "bike")
    shutil.copytree(d, b, ignore=shutil.ignore_patterns("posed_train.json", "*_rest.ply"))
    assert BikeModel.load(b).eps2d == 0.3  # parts that record no filter: 0.3
    jobs_b = [dict(j, out=j["out"].replace(d, b)) for j in jobs]
    import splatting.bike.posed_train as pt
    monkeypatch.setattr(pt, "render_posed_views", lambda *a, **k: jobs_b)  # the scene's renders stand in for Blender's
    train_bike_posed(b, PosedTrainConfig(poses=len(jobs), iterations=2, eps2d=0.173, progress=False), log=lambda m: None)
    assert BikeModel.load(b).eps2d == 0.173
    assert BikeModel.load(b, suffix="_rest").eps2d == 0.3  # the rest-trained start keeps its own

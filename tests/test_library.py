"""`python -m splatting library build` (issue 15): the task graph (views -> parts -> posed fine-tune
-> ground truth), the settings each task depends on, the manifest's quality floor, datasets
refusing untrained or below-floor assets, and (slow) a tiny two-bike build that two kills + reruns
and the Ray engine finish with the same files, whose tasks never share a file, whose
--no-posed-train parts are the posed build's rest-trained parts, and where a changed fine-tune
setting redoes only the posed and ground-truth tasks."""
from dataclasses import replace
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from cyclist_formats.errors import UserError
from helpers import ROOT, small_config, write_test_bike

PARTS = ("frame", "steering", "crank")


def _record(root, task_id, metrics, files=None):
    from splatting.library.manifest import write_record
    write_record(str(root), task_id, {"metrics": metrics, "files": files or {}, "wall_s": 1.5, "settings": {}})


def _two_bikes(tmp_path):
    a = write_test_bike(str(tmp_path / "bikes"), "city_a")
    b = write_test_bike(str(tmp_path / "bikes"), "scooter_b")
    with open(os.path.join(b, "meta.json"), "w") as f:
        json.dump({"bike_id": "scooter_b", "has_crank": False}, f)
    return {"city_a": a, "scooter_b": b}


def test_graph_orders_views_parts_posed_then_ground_truth(tmp_path):
    from splatting.library.tasks import make_graph
    g = make_graph(str(tmp_path), _two_bikes(tmp_path), ["m_adult_average_185"])
    ids = [t.id for t in g]
    assert ids == ["views:city_a", "train:city_a:frame", "train:city_a:steering", "train:city_a:crank", "posed:city_a",
                   "gt:city_a", "views:scooter_b", "train:scooter_b:frame", "train:scooter_b:steering",
                   "posed:scooter_b", "gt:scooter_b", "avatar:m_adult_average_185"]
    by = {t.id: t for t in g}
    assert by["posed:city_a"].deps == ["train:city_a:frame", "train:city_a:steering", "train:city_a:crank"]
    assert by["gt:city_a"].deps == ["posed:city_a"]
    assert by["posed:scooter_b"].deps == ["train:scooter_b:frame", "train:scooter_b:steering"]
    assert by["train:scooter_b:frame"].deps == ["views:scooter_b"]
    for t in g:  # every dependency comes earlier (the Ray engine passes refs in this order)
        assert all(ids.index(d) < ids.index(t.id) for d in t.deps)


def test_graph_without_the_posed_stage_is_the_old_one(tmp_path):
    from splatting.library.tasks import make_graph, part_file
    g = make_graph(str(tmp_path), _two_bikes(tmp_path), [], posed=False)
    assert [t.id for t in g] == ["views:city_a", "train:city_a:frame", "train:city_a:steering", "train:city_a:crank",
                                 "gt:city_a", "views:scooter_b", "train:scooter_b:frame", "train:scooter_b:steering",
                                 "gt:scooter_b"]
    assert g[4].deps == ["train:city_a:frame", "train:city_a:steering", "train:city_a:crank"]
    assert part_file("B", "frame", False) == os.path.join("B", "gaussians", "frame.ply")
    assert part_file("B", "frame", True) == os.path.join("B", "gaussians", "frame_rest.ply")


def _settings(**kw):
    from argparse import ArgumentParser

    from splatting.library.command import add_arguments, settings_of
    p = ArgumentParser()
    add_arguments(p)
    return settings_of(p.parse_args([a for k, v in kw.items() for a in (f"--{k.replace('_', '-')}", str(v))]))


def _without_posed(s):
    """The LibrarySettings s with the posed stage off (--no-posed-train)."""
    from splatting.library.settings import LibrarySettings
    return LibrarySettings(s.budget.model_copy(update={"posed_train": False}))


def test_a_changed_fine_tune_setting_clashes_with_posed_and_gt_only(tmp_path):
    """SETTING_KEYS: a fine-tune setting belongs to the posed and ground-truth tasks, never to the
    views and part trainings (those are kept); a training setting clashes with everything after views."""
    from splatting.library.manifest import check_all_settings, write_record
    from splatting.library.tasks import make_graph, task_settings
    g = make_graph(str(tmp_path), {"city_a": write_test_bike(str(tmp_path / "bikes"), "city_a")}, [])
    built = _settings(size=64, posed_iterations=20)
    rec = built.record()
    assert rec["posed_train"] is True and rec["posed_iterations"] == 20 and rec["posed_poses"] > 4
    for t in g:
        write_record(str(tmp_path), t.id, {"files": {}, "metrics": {}, "settings": task_settings(t.kind, built)})
    check_all_settings(str(tmp_path), [(t.id, task_settings(t.kind, built)) for t in g])  # same: fine

    def clash(s):
        with pytest.raises(UserError) as e:
            check_all_settings(str(tmp_path), [(t.id, task_settings(t.kind, s)) for t in g])
        return str(e.value)

    for k, v in (("posed_iterations", 30), ("posed_poses", 9), ("posed_samples", 3), ("posed_sh_degree", 0)):
        msg = clash(_settings(size=64, **dict({"posed_iterations": 20}, **{k: v})))
        assert "posed:city_a, gt:city_a)" in msg and f"({k} differ)" in msg, msg
        assert "posed__city_a.json gt__city_a.json" in msg and "train" not in msg and "views" not in msg, msg
    # a default changed in splatting/bike/posed_config.py (not an option here) is a settings change too
    assert rec["posed_rest_fraction"] > 0 and rec["posed_lr_means"] > 0
    msg = clash(replace(built, posed=built.posed.model_copy(update={"rest_fraction": rec["posed_rest_fraction"] / 2})))
    assert "(posed:city_a, gt:city_a)" in msg and "(posed_rest_fraction differ)" in msg, msg
    msg = clash(_settings(size=64, posed_iterations=20, iterations=10))
    assert "(train:city_a:frame, train:city_a:steering, train:city_a:crank, posed:city_a ...)" in msg, msg
    assert "views" not in msg
    # switching the stage off changes where the parts go: the trainings clash too
    msg = clash(_without_posed(_settings(size=64)))
    assert "train:city_a:frame" in msg and msg.endswith("built with the posed fine-tune: drop --no-posed-train"), msg


def test_settings_without_the_posed_stage_match_records_from_before_it(tmp_path):
    """A library built before the posed stage existed (records without posed keys) is the same
    library as --no-posed-train: nothing clashes, nothing is redone."""
    from splatting.library.manifest import check_all_settings, write_record
    from splatting.library.tasks import make_graph, task_settings
    g = make_graph(str(tmp_path), {"city_a": write_test_bike(str(tmp_path / "bikes"), "city_a")}, [], posed=False)
    old = {"views": ("view_size", "samples"),  # SETTING_KEYS before the posed stage
           "train": ("view_size", "samples", "iterations", "max_gaussians", "time_budget_s"),
           "gt": ("view_size", "samples", "iterations", "max_gaussians", "time_budget_s", "gt_poses", "gt_seed")}
    s = _without_posed(_settings(size=64))
    for t in g:
        write_record(str(tmp_path), t.id, {"files": {}, "metrics": {}, "settings": {k: s.record()[k] for k in old[t.kind]}})
    check_all_settings(str(tmp_path), [(t.id, task_settings(t.kind, s)) for t in g])
    posed = _settings(size=64)  # the posed stage on, over that library: the trainings clash, with the way out
    g = make_graph(str(tmp_path), {"city_a": g[0].bike_dir}, [])
    with pytest.raises(UserError, match="train:city_a:frame.*without the posed fine-tune: add --no-posed-train$"):
        check_all_settings(str(tmp_path), [(t.id, task_settings(t.kind, posed)) for t in g])


def test_posed_task_refuses_a_fine_tune_run_with_another_config(tmp_path, monkeypatch):
    """The posed record's settings must be the configuration bike-posed-train really ran (its
    posed_train.json "config"), or the record would describe other parts than the files."""
    from splatting.library import tasks
    d = write_test_bike(str(tmp_path / "bikes"), "city_a")
    s = _settings(size=64, posed_poses=6)
    cfg = {k[len("posed_"):]: v for k, v in s.record().items() if k.startswith("posed_") and k != "posed_train"}
    os.makedirs(os.path.join(d, "gaussians"), exist_ok=True)
    os.makedirs(os.path.join(d, "views", "posed"), exist_ok=True)
    for p in PARTS:
        open(os.path.join(d, "gaussians", p + ".ply"), "wb").close()
    ran = []
    monkeypatch.setattr(tasks, "_run", lambda cmd, what: ran.append(cmd))  # the subprocess "ran" with cfg
    task = tasks.make_graph(str(tmp_path), {"city_a": d}, [])[4]
    assert task.id == "posed:city_a"
    for config, ok in ((cfg, True), (dict(cfg, iterations=cfg["iterations"] + 1), False)):
        with open(os.path.join(d, "gaussians", "posed_train.json"), "w") as f:
            json.dump({"config": config, "held_out_box_psnr_after": 30.0, "poses": 6}, f)
        if ok:
            rec = tasks.run_posed(task, str(tmp_path), s)
            assert rec["metrics"]["held_out_box_psnr_after"] == 30.0 and len(rec["files"]) == 5
        else:
            with pytest.raises(RuntimeError, match=r"another configuration .*\(iterations\)"):
                tasks.run_posed(task, str(tmp_path), s)
    assert "--from-rest" in ran[0] and ran[0][ran[0].index("--poses") + 1] == "6"


def test_fidelity_recipe_trains_antialiased_and_runs_its_fine_tune(tmp_path, monkeypatch):
    """--recipe fidelity (splatting/bike/recipes.py): the train tasks pass --antialiased and the posed
    task passes every recipe option, so the configuration bike-posed-train parses from its command
    line is the recipe's (what run_posed checks against posed_train.json); the default recipe adds
    no setting, so libraries built before the option still match."""
    import argparse

    from splatting.bike.command import PosedTrain
    from splatting.bike.recipes import posed_config
    from splatting.library import tasks
    d = write_test_bike(str(tmp_path / "bikes"), "city_a")
    fid, default = _settings(size=64, recipe="fidelity"), _settings(size=64)
    assert fid.record()["antialiased"] is True and "antialiased" not in default.record()
    assert "antialiased" in tasks.task_settings("train", fid) and "antialiased" not in tasks.task_settings("train", default)
    assert fid.record()["posed_eps2d"] == 0.173 and fid.record()["posed_densify"] and fid.record()["posed_iterations"] == 10000
    assert _settings(size=64, recipe="fidelity", posed_iterations=50).record()["posed_iterations"] == 50  # options override
    ran = []
    monkeypatch.setattr(tasks, "_run", lambda cmd, what: ran.append(cmd) or "")
    g = tasks.make_graph(str(tmp_path), {"city_a": d}, [])
    train, posed = g[1], g[4]
    with pytest.raises(FileNotFoundError):  # the fake run wrote no metrics: only the command matters
        tasks.run_train(train, str(tmp_path), fid)
    assert "--antialiased" in ran[-1]
    with pytest.raises(FileNotFoundError):
        tasks.run_train(train, str(tmp_path), default)
    assert "--antialiased" not in ran[-1]
    with pytest.raises(FileNotFoundError):
        tasks.run_posed(posed, str(tmp_path), fid)
    p = argparse.ArgumentParser()
    PosedTrain.add_arguments(p)
    cmd = ran[-1]
    args = p.parse_args(cmd[cmd.index("bike-posed-train") + 1:])
    assert PosedTrain.config_from_args(args) == posed_config("fidelity", samples=fid.posed.samples, progress=False)


def _manifest(tmp_path, gt_iou, part_psnr=30.0, complete=True):
    from splatting.library.manifest import build_manifest
    from splatting.library.settings import Floors
    from splatting.library.tasks import make_graph
    d = write_test_bike(str(tmp_path / "bikes"), "city_a")
    g = make_graph(str(tmp_path), {"city_a": d}, [])
    _record(tmp_path, "views:city_a", {"views": 144})
    for p in ("frame", "steering", "crank"):
        _record(tmp_path, f"train:city_a:{p}", {"psnr": part_psnr, "box_psnr": part_psnr - 5},
                {f"bikes/city_a/gaussians/{p}_rest.ply": "ab" * 32})
    _record(tmp_path, "posed:city_a", {"held_out_box_psnr_before": 29.5, "held_out_iou_before": 0.97,
                                       "held_out_box_psnr_after": 31.2, "held_out_iou_after": 0.975},
            {f"bikes/city_a/gaussians/{p}.ply": "cd" * 32 for p in ("frame", "steering", "crank")})
    if complete:
        _record(tmp_path, "gt:city_a", {"gt_iou": gt_iou, "gt_box_psnr": 25.0, "gt_iou_min": gt_iou,
                                        "gt_box_psnr_min": 24.0, "gt_poses": 3})
    return build_manifest(str(tmp_path), g, Floors(), _settings(size=64), "local")


def test_manifest_marks_assets_below_the_floor(tmp_path):
    good = _manifest(tmp_path / "good", gt_iou=0.95)["bikes"]["city_a"]
    assert good["usable"] and good["complete"] and good["below_floor"] == []
    assert good["quality"]["part_psnr"] == {"frame": 30.0, "steering": 30.0, "crank": 30.0}
    assert good["quality"]["posed_box_psnr"] == 31.2 and good["quality"]["posed_iou"] == 0.975
    assert good["quality"]["posed_box_psnr_before"] == 29.5
    assert good["build_s"] == 9.0 and len(good["files"]) == 6
    low = _manifest(tmp_path / "low", gt_iou=0.5)["bikes"]["city_a"]
    assert not low["usable"] and "IoU" in low["below_floor"][0]
    blurry = _manifest(tmp_path / "blurry", gt_iou=0.95, part_psnr=12.0)["bikes"]["city_a"]
    assert not blurry["usable"] and len(blurry["below_floor"]) == 3
    unfinished = _manifest(tmp_path / "unfinished", gt_iou=0.95, complete=False)["bikes"]["city_a"]
    assert not unfinished["usable"] and not unfinished["complete"]
    with open(tmp_path / "good" / "library.json") as f:
        assert json.load(f)["bikes"]["city_a"]["usable"] is True


def _trained(d):
    os.makedirs(os.path.join(d, "gaussians"), exist_ok=True)
    for p in ("frame", "steering", "crank"):
        open(os.path.join(d, "gaussians", p + ".ply"), "wb").close()


def test_datasets_use_trained_usable_assets_only(tmp_path):
    from splatting.dataset.config import validate
    from splatting.library.use import check_dataset_assets
    root = tmp_path / "lib"
    d = write_test_bike(str(root / "bikes"), "city_a")
    cfg = validate(small_config(str(root / "bikes"), bikes=["city_a"], mode="bike-only", synthetic_assets="auto"))
    with pytest.raises(UserError, match="library build --out .* --bikes city_a"):
        check_dataset_assets(cfg)
    check_dataset_assets(cfg.model_copy(update={"synthetic_assets": "always"}))  # the explicit opt-in to stand-ins
    _trained(d)
    check_dataset_assets(cfg)  # trained, no manifest: fine
    _manifest(root, gt_iou=0.5)  # library.json beside bikes/ marks city_a below the floor
    with pytest.raises(UserError, match="unusable .*IoU"):
        check_dataset_assets(cfg)
    check_dataset_assets(cfg, allow_low_quality=True)
    rider_cfg = validate(small_config(str(root / "bikes"), bikes=["city_a"], synthetic_assets="never"))
    _manifest(root, gt_iou=0.95)
    with pytest.raises(UserError, match="no trained avatar .*--riders m_adult_average_185"):
        check_dataset_assets(rider_cfg)


def test_dataset_command_names_the_build_command(tmp_path):
    from helpers import write_yaml
    write_test_bike(str(tmp_path / "bikes"), "city_a")
    cfg = small_config(str(tmp_path / "bikes"), bikes=["city_a"], mode="bike-only", synthetic_assets="auto")
    path = write_yaml(str(tmp_path / "c.yaml"), cfg)
    r = subprocess.run([sys.executable, "-m", "splatting", "dataset", "--config", path, "--out", str(tmp_path / "d")],
                       cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "python -m splatting library build" in r.stderr and "synthetic_assets: always" in r.stderr
    assert not os.path.exists(tmp_path / "d")


# -- a real build (Blender views, training, Blender ground truth): minutes -----------------------

TINY = ["--size", "64", "--samples", "2", "--iterations", "60", "--max-gaussians", "1500", "--gt-poses", "1",
        "--quiet"]
POSED = ["--posed-poses", "6", "--posed-iterations", "20"]  # 2 training + 4 held-out posed renders


def _build(out, *extra, posed=POSED):
    return subprocess.run([sys.executable, "-m", "splatting", "library", "build", "--out", out, *TINY, *posed, *extra],
                          cwd=ROOT, capture_output=True, text=True, env=dict(os.environ, OMP_NUM_THREADS="1"))


def _asset_hashes(out):
    with open(os.path.join(out, "library.json")) as f:
        doc = json.load(f)
    return {b: a["files"] for b, a in doc["bikes"].items()}, doc


# What may differ between two builds of the same library: Blender stamps each PNG with the .blend
# path, date and render time (metadata chunks), the metrics JSON records wall times, and the posed
# renders' poses.json names its files and cameras by absolute path (the library root differs).
# Everything else - pixels, Gaussians, metrics - must be equal.
TIMING_KEYS = {"wall_s", "eval_s", "views", "psnr_history"}


def _content(path, root):
    if path.endswith(".png"):
        import numpy as np
        from PIL import Image
        with Image.open(path) as im:
            return np.asarray(im).tobytes()
    if path.endswith(".json"):
        with open(path) as f:
            d = json.load(f)
        text = json.dumps({k: v for k, v in d.items() if k not in TIMING_KEYS}, sort_keys=True) \
            if isinstance(d, dict) else json.dumps(d)
        return text.replace(os.path.abspath(root), "<OUT>")
    with open(path, "rb") as f:
        return f.read()


def same_library(a, b):
    """Every asset file of library a equals b's (see TIMING_KEYS); returns how many were compared."""
    n = 0
    for sub in ("bikes", os.path.join("library", "gt")):
        for d, _, files in os.walk(os.path.join(a, sub)):
            for name in files:
                if name.endswith(".blend") or name.startswith("."):
                    continue
                pa = os.path.join(d, name)
                pb = os.path.join(b, os.path.relpath(pa, a))
                assert os.path.isfile(pb), pb
                assert _content(pa, a) == _content(pb, b), os.path.relpath(pa, a)
                n += 1
    return n


def _read(path):
    with open(path, "rb") as f:
        return f.read()


def _records(out):
    tasks = os.path.join(out, "library", "tasks")
    recs = {}
    for f in sorted(os.listdir(tasks)):
        with open(os.path.join(tasks, f)) as fh:
            recs[f[:-5]] = json.load(fh)
    return recs


def _kill_when(out, ready, what):
    """Start a build of out, SIGKILL it (driver, Blender, training) once ready() holds."""
    p = subprocess.Popen([sys.executable, "-m", "splatting", "library", "build", "--out", out, *TINY, *POSED],
                         cwd=ROOT, env=dict(os.environ, OMP_NUM_THREADS="1"), start_new_session=True,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while p.poll() is None and time.time() - t0 < 900 and not ready():
        time.sleep(0.1)
    os.killpg(p.pid, signal.SIGKILL)
    p.wait()
    assert not os.path.exists(os.path.join(out, "library.json")), f"killed too late ({what})"


@pytest.mark.slow
def test_tiny_library_build_killed_rerun_and_ray_give_the_same_files(tmp_path):
    import shutil
    bikes = str(tmp_path / "seed")
    # three-part bikes: what is compared here is kill / rerun / Ray against one whole build (the wheel
    # and pedal sub-parts' views and training: tests/test_sub_parts.py, and read_ply's empty-part test)
    r = subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "make_bikes.py"), "--out", bikes,
                        "--count", "2", "--no-extras", "--no-sub-parts"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    copies = {k: str(tmp_path / k) for k in ("whole", "killed", "ray", "quick")}
    for c in copies.values():
        shutil.copytree(bikes, c)
    r = _build(copies["whole"], "--workers", "2")
    assert r.returncode == 0, r.stderr
    ref, doc = _asset_hashes(copies["whole"])
    ids = sorted(os.listdir(os.path.join(bikes, "bikes")))
    assert sorted(ref) == ids
    for b in doc["bikes"].values():
        assert b["complete"] and b["quality"]["gt_poses"] == 1 and 0 <= b["quality"]["gt_iou"] <= 1
        assert set(b["quality"]["part_psnr"]) == set(PARTS)
        assert 0 <= b["quality"]["posed_iou"] <= 1 and b["quality"]["posed_box_psnr"] > 0
        g = os.path.join(copies["whole"], b["folder"], "gaussians")
        assert sorted(os.listdir(g)) == sorted([f"{p}.ply" for p in PARTS] + [f"{p}_rest.{e}" for p in PARTS
                                                                             for e in ("ply", "json")]
                                               + ["posed_train.json"])
        for p in PARTS:  # the posed task fine-tuned what the train task left
            assert _read(os.path.join(g, p + ".ply")) != _read(os.path.join(g, p + "_rest.ply"))
    recs = _records(copies["whole"])
    assert len(recs) == 12 and all(recs[f"posed__{b}"]["metrics"]["poses"] == 6 for b in ids)
    owner = {}
    for tid, rec in recs.items():  # one owner per file
        for f in rec["files"]:
            assert f not in owner, f"{f} written by {owner[f]} and {tid}"
            owner[f] = tid
    assert owner[f"bikes/{ids[0]}/gaussians/frame.ply"] == f"posed__{ids[0]}"
    assert owner[f"bikes/{ids[0]}/gaussians/frame_rest.ply"] == f"train__{ids[0]}__frame"
    # killed after its first trained part, rerun and killed again in its first fine-tune, then rerun
    tasks = os.path.join(copies["killed"], "library", "tasks")
    _kill_when(copies["killed"], lambda: os.path.isdir(tasks) and any(f.startswith("train") for f in os.listdir(tasks)),
               "first part")
    _kill_when(copies["killed"], lambda: os.path.isdir(os.path.join(copies["killed"], "bikes", ids[0], "views", "posed")),
               "first fine-tune")
    assert not os.path.exists(os.path.join(tasks, f"posed__{ids[0]}.json")), "killed too late (first fine-tune)"
    r = _build(copies["killed"])
    assert r.returncode == 0, r.stderr
    assert same_library(copies["whole"], copies["killed"]) > 450
    assert {b: sorted(f) for b, f in _asset_hashes(copies["killed"])[0].items()} == {b: sorted(f) for b, f in ref.items()}
    r = _build(copies["ray"], "--engine", "ray")
    assert r.returncode == 0, r.stderr
    assert same_library(copies["whole"], copies["ray"]) > 450
    # --no-posed-train: today's layout, and its parts are the posed build's rest-trained parts
    # (the views are reused from the posed build: their record does not depend on the posed stage)
    b, q = ids[0], copies["quick"]
    for part in ("frame", "steering", "crank", "whole"):
        shutil.copytree(os.path.join(copies["whole"], "bikes", b, "views", part), os.path.join(q, "bikes", b, "views", part))
    os.makedirs(os.path.join(q, "library", "tasks"))
    shutil.copy(os.path.join(copies["whole"], "library", "tasks", f"views__{b}.json"), os.path.join(q, "library", "tasks"))
    r = _build(q, "--bikes", b, "--no-posed-train", posed=[])
    assert r.returncode == 0, r.stderr
    assert "5 tasks (4 run, 1 done earlier)" in r.stdout, r.stdout
    g = os.path.join(q, "bikes", b, "gaussians")
    assert sorted(os.listdir(g)) == sorted(f"{p}.{e}" for p in PARTS for e in ("ply", "json"))
    assert not os.path.exists(os.path.join(q, "bikes", b, "views", "posed"))
    wg = os.path.join(copies["whole"], "bikes", b, "gaussians")
    for p in PARTS:
        assert _read(os.path.join(g, p + ".ply")) == _read(os.path.join(wg, p + "_rest.ply"))
    quick = _asset_hashes(q)[1]["bikes"][b]
    assert quick["complete"] and "posed_box_psnr" not in quick["quality"]
    assert quick["quality"]["part_psnr"] == doc["bikes"][b]["quality"]["part_psnr"]
    # a changed fine-tune setting: refused naming the posed and ground-truth records; once those
    # are deleted, only they are redone (the trained parts stay, byte for byte)
    w = copies["whole"]
    before = {f: _read(os.path.join(wg, f)) for f in os.listdir(wg)}
    more = ["--posed-poses", "6", "--posed-iterations", "30"]
    r = _build(w, "--bikes", b, posed=more)
    assert r.returncode == 2 and f"(posed:{b}, gt:{b})" in r.stderr and "train:" not in r.stderr, r.stderr
    for t in (f"posed__{b}", f"gt__{b}"):
        os.remove(os.path.join(w, "library", "tasks", t + ".json"))
    r = _build(w, "--bikes", b, posed=more)
    assert r.returncode == 0, r.stderr
    assert "6 tasks (2 run, 4 done earlier)" in r.stdout, r.stdout
    after = {f: _read(os.path.join(wg, f)) for f in before}
    assert all(after[f] == before[f] for f in before if "_rest." in f)
    assert all(after[f"{p}.ply"] != before[f"{p}.ply"] for p in PARTS)
    assert _records(w)[f"posed__{b}"]["settings"]["posed_iterations"] == 30


def test_an_avatar_task_records_its_look_beside_its_gaussians(tmp_path, monkeypatch):
    """The avatar task's files are what the manifest hashes and datasets read: look.json (what the
    avatar wears, read when accessories are drawn) is one of them when rider-avatar wrote it."""
    from splatting.library import tasks

    folder = tmp_path / "riders" / "m_adult_average_185"

    def fake_avatar(cmd, what, env_threads=1):  # what rider-avatar leaves in its --out folder
        folder.mkdir(parents=True)
        for n in (tasks.PLY_NAME, tasks.SKINNING_NAME):
            (folder / n).write_bytes(b"x")
        (folder / "rider.json").write_text(json.dumps({"psnr": 40.0, "psnr_crop": 35.0, "gaussians": 10}))
        (folder / tasks.LOOK_NAME).write_text("{}")
        return ""

    monkeypatch.setattr(tasks, "_run", fake_avatar)
    s = _settings(size=64, riders_root=str(tmp_path / "riders"))
    rec = tasks.run_avatar(tasks.Task("avatar:m_adult_average_185", "avatar", "m_adult_average_185"), str(tmp_path), s)
    assert sorted(os.path.basename(p) for p in rec["files"]) == sorted(
        [tasks.PLY_NAME, tasks.SKINNING_NAME, "rider.json", "look.json"])
    assert rec["metrics"] == {"psnr": 40.0, "box_psnr": 35.0, "gaussians": 10}

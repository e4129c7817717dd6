"""Benchmark bookkeeping (bench/provenance.py, bench/run.py): reused artefacts are keyed by what made
them, every results key says where it came from, and a stage that measured nothing leaves a
"not measured: <reason>" row in report.md.  Fast: no Blender, no training."""
import json
import os

import numpy as np
import pytest

from bench import provenance, run as bench_run
from bench.compare import renders_for


def test_renders_for_keeps_renders_of_the_same_key_only(tmp_path):
    d = str(tmp_path / "gt")
    key = {"bike": "/b", "blend": "aa11", "poses": [[1.0, 2.0]], "code": "c0"}
    renders_for(d, key, prefix=("gt_", "passes_"))
    for f in ("gt_000.png", "passes_000.exr", "job.json"):
        (tmp_path / "gt" / f).write_text("x")
    renders_for(d, json.loads(json.dumps(key)))   # the same key (as read back from JSON): kept
    assert sorted(os.listdir(d)) == ["gt_000.png", "job.json", "key.json", "passes_000.exr"]
    for change in ({"blend": "bb22"}, {"code": "c1"}, {"poses": [[1.0, 2.5]]}):
        (tmp_path / "gt" / "gt_000.png").write_text("x")
        renders_for(d, {**key, **change}, prefix=("gt_", "passes_"))
        assert not os.path.exists(os.path.join(d, "gt_000.png")), change   # another bike file / code / pose
        assert os.path.exists(os.path.join(d, "job.json"))                 # not a render: left alone
        renders_for(d, key, prefix=("gt_", "passes_"))


def test_hashes_follow_content_not_names_or_times(tmp_path):
    a = tmp_path / "a"
    a.mkdir()
    (a / "x.py").write_text("print(1)\n")
    (a / "notes.txt").write_text("n")
    h = provenance.tree_hash(str(a))
    os.utime(a / "x.py", (1, 1))
    assert provenance.tree_hash(str(a)) == h                      # a touched file: same content, same hash
    (a / "x.py").write_text("print(2)\n")
    assert provenance.tree_hash(str(a)) != h
    assert provenance.tree_hash(str(a), (".py",)) != provenance.tree_hash(str(a))
    assert provenance.tree_hash(str(tmp_path / "nope")) == "missing"
    bike = tmp_path / "bike"
    bike.mkdir()
    for f in ("bike.blend", "keypoints.json", "meta.json"):
        (bike / f).write_bytes(b"1")
    k1 = provenance.bike_assets(str(bike))
    (bike / "bike.blend").write_bytes(b"2")                         # same name, other model
    k2 = provenance.bike_assets(str(bike))
    assert k1 != k2 and k1["bike"] == k2["bike"] == str(bike)
    assert len(provenance.code_version(*provenance.RENDER_CODE)) == 16


def test_a_relight_fit_of_other_gaussians_is_stale(tmp_path):
    """Same Gaussian count, other Gaussians: the fit must be redone (the count check alone passed it)."""
    from cyclist_formats import bike_folder
    from splatting.relight.fit import RelightFitConfig

    ply, views = tmp_path / "frame.ply", tmp_path / "views"
    views.mkdir()
    (views / "cameras.json").write_text("{}")
    ply.write_bytes(b"gaussians v1")
    z = np.zeros((4, 3), np.float32)
    bike_folder.write_relight(str(ply), albedo=z, normal=z, gloss=z)
    cfg = RelightFitConfig()
    current, path, key = provenance.relight_fit_is_current(str(ply), str(views), cfg)
    assert not current                                # no key recorded: not known to be current
    provenance.write_key(path, key)
    assert provenance.relight_fit_is_current(str(ply), str(views), cfg)[0]
    ply.write_bytes(b"gaussians v2")                  # retrained, same count
    assert not provenance.relight_fit_is_current(str(ply), str(views), cfg)[0]
    ply.write_bytes(b"gaussians v1")
    assert not provenance.relight_fit_is_current(str(ply), str(views), RelightFitConfig(iterations=cfg.iterations + 1))[0]
    (views / "cameras.json").write_text('{"c": 1}')
    assert not provenance.relight_fit_is_current(str(ply), str(views), cfg)[0]


def test_fidelity_runs_are_reused_only_with_the_same_key_and_marked(tmp_path, monkeypatch):
    from bench import train_chart
    import splatting.training.trainer as trainer
    import splatting.training.views as views_mod

    trained = []
    monkeypatch.setattr(trainer, "train_views", lambda v, cfg: trained.append(cfg.threads) or (None, {
        "psnr_crop": 30.0, "gaussians": 10, "wall_s": 5.0, "iterations": 7, "stopped": "iterations"}))
    monkeypatch.setattr(views_mod, "load_views", lambda d: d)
    monkeypatch.setattr(train_chart, "clean_fidelity", lambda g, ref, aa, eps: (31.0, 0.98, 4))
    monkeypatch.setattr(train_chart, "draw_fidelity", lambda runs, png, title="": None)
    ref, v = tmp_path / "ref", tmp_path / "views"
    ref.mkdir()
    v.mkdir()
    (ref / "cameras.json").write_text("{}")
    (v / "cameras.json").write_text("{}")
    specs = [{"label": "a", "views": str(v), "max_gaussians": 100}]
    png = str(tmp_path / "c.png")
    first = train_chart.run_fidelity(specs, str(ref), png, threads=1)
    assert len(trained) == 1 and first[0]["reused"] is False
    again = train_chart.run_fidelity(specs, str(ref), png, threads=1)
    assert len(trained) == 1 and again[0]["reused"] is True and again[0]["clean_box_psnr"] == 31.0
    train_chart.run_fidelity(specs, str(ref), png, threads=2)          # other thread count: trained again
    (ref / "cameras.json").write_text('{"x": 1}')                      # other reference content: again
    train_chart.run_fidelity(specs, str(ref), png, threads=2)
    assert trained == [1, 2, 2]


def test_bike_fidelity_wall_time_needs_every_parts_metrics(tmp_path):
    from bench.train_chart import _wall_s

    p = tmp_path / "frame.json"
    p.write_text(json.dumps({"wall_s": 12.5}))
    assert _wall_s(str(p), "frame") == 12.5
    with pytest.raises(ValueError, match="steering"):
        _wall_s(None, "part steering")                       # no metrics JSON: an error, not +0 s
    p.write_text(json.dumps({"psnr": 30}))
    with pytest.raises(ValueError, match="frame"):
        _wall_s(str(p), "part frame")


def test_report_marks_provenance_and_not_measured_rows():
    results = {"bike_gt": {"poses": 20, "iou_mean": 0.97}, "train_parts": [
        {"bike": "b", "part": "frame", "psnr": 33.0, "ssim": 0.99, "gaussians": 9, "wall_s": 100.0, "reused": True}]}
    provenance.record(results, "bike_gt", "fresh", bike="/x/b", blender_renders="reused (same key)")
    provenance.record(results, "train_parts", "reused")
    provenance.not_measured(results, "bike_relit", "no bike with passes")
    text = "\n".join(bench_run.report_lines(results, {}))
    assert "| key | value | provenance | target | paper |" in text and "| this run |" not in text
    row = next(line for line in text.splitlines() if line.startswith("| `bike_gt`"))
    assert "fresh (bike: /x/b; blender_renders: reused (same key))" in row
    assert "| `bike_relit` | not measured: no bike with passes |" in text
    # a target nobody measured or skipped still gets its row
    assert "| `ik_iter_ms` | not measured: no stage of this run reported it |" in text
    assert "| b | frame | 33.00 | 0.9900 | 9 | 100 | reused |" in text
    assert "`provenance`" not in text and "`not_measured`" not in text


def test_run_records_fresh_keys_failed_and_silent_stages(tmp_path, monkeypatch):
    def ok(m, r, out):
        r["ik_iter_ms"] = 1.0

    def boom(m, r, out):
        raise RuntimeError("worker died\nmore")

    monkeypatch.setattr(bench_run, "STAGES", {"ik": ("bench.provenance", ok), "bike_gt": ("bench.provenance", boom),
                                              "rider": ("bench.provenance", lambda m, r, out: None)})
    assert bench_run.main(["--out", str(tmp_path), "--stages", "ik,bike_gt,rider"]) == 1
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["provenance"]["ik_iter_ms"] == {"status": "fresh", "stage": "ik"}
    assert res["not_measured"] == {"stage bike_gt": "failed: RuntimeError: worker died",
                                   "stage rider": "the stage added no key (see its log)"}
    report = (tmp_path / "report.md").read_text()
    assert "| `stage bike_gt` | not measured: failed: RuntimeError: worker died |" in report
    assert "| `stage rider` | not measured: the stage added no key (see its log) |" in report


def _bike(d, files=("bike.blend", "gaussians/frame.ply", "gaussians/steering.ply", "views/whole/cameras.json")):
    for f in files:
        p = os.path.join(d, f)
        os.makedirs(os.path.dirname(p), exist_ok=True)
        with open(p, "w") as fh:
            fh.write("x")
    return d


def test_blender_compare_records_the_bike_and_its_fallback(tmp_path, monkeypatch):
    """No silent substitution: a bike taken from out/demo/bikes (none under the bench's own bikes/)
    is recorded with its full path and the fallback, in the key and its provenance."""
    from bench import blender_compare as bc

    monkeypatch.setattr(bc, "ROOT", str(tmp_path / "repo"))
    monkeypatch.setattr(bc, "run_compare", lambda *a, **k: ([{"method": bc.GAUSS, "box_psnr": 30.0, "iou": 0.95,
                                                               "s_2p": 1.0}], []))
    monkeypatch.setattr(bc, "chart", lambda *a, **k: None)
    monkeypatch.setattr(bc, "table", lambda rows: [])
    out = tmp_path / "bench"
    out.mkdir()
    res = {}
    assert bc.run(res, str(out), progress=lambda m: None) is None          # no bike anywhere: not measured
    assert set(res["not_measured"]) >= {"blender_compare", "bike_fidelity"}
    demo = _bike(str(tmp_path / "repo" / "out" / "demo" / "bikes" / "city_00"))
    res = {}
    bc.run(res, str(out), progress=lambda m: None)
    assert res["blender_compare"]["bike_dir"] == demo and "demo" in res["blender_compare"]["bike_fallback"]
    assert res["provenance"]["bike_fidelity"]["fallback"] == res["blender_compare"]["bike_fallback"]
    own = _bike(str(out / "bikes" / "city_00"))
    res = {}
    bc.run(res, str(out), progress=lambda m: None)
    assert res["blender_compare"]["bike_dir"] == own and res["blender_compare"]["bike_fallback"] is None
    assert "fallback" not in res["provenance"]["blender_compare"]


def test_ik_bench_refuses_an_unreadable_bike(tmp_path):
    from bench import ik as bench_ik
    from cyclist_formats.errors import UserError

    good = tmp_path / "city_00"
    good.mkdir()
    (good / "meta.json").write_text(json.dumps({"has_crank": True}))
    kp = {k: [0.0, 0.5, 0.0] for k in ("seat", "crank_axle")}
    (good / "keypoints.json").write_text(json.dumps({"keypoints": kp}))
    assert [b for b, _, _ in bench_ik.library_bikes(str(tmp_path))] == ["city_00"]
    assert bench_ik.LIBRARY_SOURCE[0].startswith("bicycles of")
    bad = tmp_path / "road_00"
    bad.mkdir()
    (bad / "keypoints.json").write_text(json.dumps({"keypoints": kp}))
    (bad / "meta.json").write_text("{broken")
    with pytest.raises(UserError, match="road_00"):
        bench_ik.library_bikes(str(tmp_path))

"""bench/blender_compare.py: the equal-fidelity key from hand numbers, and the whole stage (persistent
Blender and Gaussian workers, references, interleaved timing, table, chart) on a tiny setting."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CURVE = [(1, 20.0, 0.1), (2, 24.0, 0.2), (4, 28.0, 0.4), (8, 32.0, 0.8)]


def test_match_interpolates_in_log_spp():
    from bench.blender_compare import match_cycles

    m = match_cycles(CURVE, 30.0)  # halfway from 28 dB (4 spp) to 32 dB (8 spp)
    assert m["bound"] == "interpolated"
    assert m["spp"] == pytest.approx(2 ** 2.5)
    assert m["s_per_image"] == pytest.approx(0.6)
    m = match_cycles(CURVE, 25.0)  # a quarter of the way from 2 to 4 spp
    assert m["spp"] == pytest.approx(2 ** 1.25) and m["s_per_image"] == pytest.approx(0.25)


def test_match_outside_the_measured_range():
    from bench.blender_compare import match_cycles

    assert match_cycles(CURVE, 19.0) == {"spp": 1.0, "s_per_image": 0.1, "bound": "at_min"}
    assert match_cycles(CURVE, 40.0) == {"spp": 8.0, "s_per_image": 0.8, "bound": "above_max"}
    assert match_cycles([], 30.0) is None
    # the first crossing counts even when a later sample count dips below the target again
    assert match_cycles([(1, 20.0, 0.1), (2, 31.0, 0.2), (4, 29.0, 0.4)], 30.0)["spp"] == pytest.approx(2 ** (10 / 11))


def test_key_is_ours_per_hour_over_the_cheapest_family():
    from bench.blender_compare import equal_fidelity

    rows = [{"method": "gaussians", "box_psnr": 30.0, "s_2p": 0.05}]
    rows += [{"method": f"c{s}", "family": "cycles", "spp": s, "box_psnr": p, "s_2p": t} for s, p, t in CURVE]
    # denoised: reaches 30 dB between 2 spp (29 dB, 0.25 s) and 4 spp (33 dB, 0.45 s): 0.30 s
    rows += [{"method": f"d{s}", "family": "cycles_denoised", "spp": s, "box_psnr": p, "s_2p": t}
             for s, p, t in [(1, 26.0, 0.15), (2, 29.0, 0.25), (4, 33.0, 0.45)]]
    ratio, match = equal_fidelity(rows)
    assert match["family"] == "cycles_denoised"
    assert match["s_per_image"] == pytest.approx(0.30)
    assert match["spp"] == pytest.approx(2 ** 1.25)
    assert ratio == pytest.approx(0.30 / 0.05)
    assert match["gaussian_images_per_hour"] == pytest.approx(72000)


@pytest.fixture(scope="module")
def trained_bike(tmp_path_factory):
    """A procedural bike with stand-in part Gaussians on its mesh surface and a ring cameras.json."""
    pytest.importorskip("bpy")
    torch = pytest.importorskip("torch")
    out = tmp_path_factory.mktemp("cmp")
    r = subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "make_bikes.py"), "--out", str(out),
                        "--count", "1", "--seed", "5", "--no-extras"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    bike = out / "bikes" / sorted(os.listdir(out / "bikes"))[0]
    code = (
        "import sys, numpy as np; sys.path.insert(0, %r)\n"
        "from addon.core.render import render\nfrom addon.core.bike_asset import open_bike\n"
        "b = open_bike(%r)\n"
        "np.savez(%r, **{k: render.sample_surface(render.mesh_world_triangles(o), 3000, seed=1)[0]"
        " for k, o in b['parts'].items()})\n" % (ROOT, str(bike), str(out / "pts.npz")))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    from cyclist_formats import bike_folder, ring
    from splatting.gaussians.container import Gaussians, write_ply

    os.makedirs(bike / "gaussians")
    for part, p in np.load(out / "pts.npz").items():
        n = len(p)
        g = Gaussians(means=torch.tensor(p, dtype=torch.float32), quats=torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                      log_scales=torch.full((n, 3), math.log(0.01)), opacity_logits=torch.full((n,), 3.0),
                      sh=torch.zeros(n, 1, 3))
        write_ply(g, bike / "gaussians" / f"{part}.ply")
    views = bike / "views" / "whole"
    os.makedirs(views)
    bike_folder.write_views_meta(str(views), ring.ring([0.0, 0.5, 0.0]))
    return bike


@pytest.mark.slow  # ~2-5 min: a procedural bike, four worker processes, 16-spp references
def test_stage_on_a_tiny_setting(trained_bike, tmp_path):
    from bench.blender_compare import GAUSS, equal_fidelity, match_cycles, run

    res = {}
    rows = run(res, str(tmp_path), str(trained_bike), n_poses=2, size=48, spp=(1, 4), reference_spp=16,
               progress=lambda s: None)
    names = [r["method"] for r in rows]
    assert names == ["cycles_1spp", "cycles_4spp", "cycles_1spp_denoised", "cycles_4spp_denoised", "workbench", GAUSS]
    for r in rows:
        assert r["s_2t"] > 0 and r["s_2p"] > 0 and 0 <= r["iou"] <= 1 and math.isfinite(r["box_psnr"])
    ours = rows[-1]
    assert ours["s_1t"] > 0
    # the stand-in Gaussians (1 cm blobs on the mesh surface) fill the wheels, so IoU is low, but
    # their silhouette must cover the reference's: same pose, same camera on both sides
    from bench.compare import load_rgba

    for i in range(2):
        _, m_ref = load_rgba(tmp_path / "blender_compare" / "reference" / f"ref_{i:03d}.png")
        _, m_g = load_rgba(tmp_path / "blender_compare" / f"gaussians_{i:03d}.png")
        assert m_ref.sum() > 20 and (m_ref & m_g).sum() / m_ref.sum() > 0.8
    # the key is the stage's own rows put through the hand-checked matcher
    fams = {f: [(r["spp"], r["box_psnr"], r["s_2p"]) for r in rows if r.get("family") == f]
            for f in ("cycles", "cycles_denoised")}
    cheapest = min(match_cycles(c, ours["box_psnr"])["s_per_image"] for c in fams.values())
    assert res["gaussian_vs_blender_equal_fidelity"] == pytest.approx(cheapest / ours["s_2p"])
    assert res["gaussian_vs_blender_equal_fidelity"] == pytest.approx(equal_fidelity(rows)[0])
    assert res["blender_compare"]["rows"] == rows
    assert (tmp_path / "gaussian_vs_blender.png").stat().st_size > 1000
    table = (tmp_path / "blender_compare_table.md").read_text()
    assert "| gaussians |" in table and "gaussian_vs_blender_equal_fidelity" in table
    per_pose = json.loads((tmp_path / "blender_compare" / "per_pose.json").read_text())
    assert len(per_pose) == 2 * len(rows)
    # every method rendered each pose at the requested size, and the references are at 16 spp
    from PIL import Image

    assert Image.open(tmp_path / "blender_compare" / "gaussians_001.png").size == (48, 48)
    job = json.loads((tmp_path / "blender_compare" / "reference" / "job.json").read_text())
    assert job["reference_spp"] == 16 and job["size"] == 48


def test_cli_rejects_bad_input(tmp_path):
    for args, word in ((["--poses", "0"], "--poses"), (["--size", "3"], "--size"), (["--spp", "1,x"], "--spp"),
                       (["--bike", str(tmp_path / "nope")], "bike")):
        r = subprocess.run([sys.executable, "-m", "bench.blender_compare", "--out", str(tmp_path / "o"), *args],
                           cwd=ROOT, capture_output=True, text=True)
        assert r.returncode == 2, r.stderr
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and word in lines[0], r.stderr
    assert not (tmp_path / "o").exists()


def test_renders_for_keeps_renders_of_the_same_key_only(tmp_path):
    """The relit benches' Blender renders are reused only for the poses, lights and reference
    settings they were made for: another key deletes them (the workers skip existing files)."""
    from bench.compare import REFERENCE, renders_for

    key = {"poses": [[1.0, 2.0]], "reference": REFERENCE}
    d = renders_for(str(tmp_path / "gt"), key)
    (tmp_path / "gt" / "gt_000.png").write_bytes(b"x")
    (tmp_path / "gt" / "camera_000.json").write_text("{}")
    assert renders_for(d, dict(key)) == d and (tmp_path / "gt" / "gt_000.png").exists()  # same key: kept
    renders_for(d, dict(key, reference=dict(REFERENCE, samples=16)))  # e.g. the old 16-sample ground truth
    assert not (tmp_path / "gt" / "gt_000.png").exists() and (tmp_path / "gt" / "camera_000.json").exists()
    assert json.loads((tmp_path / "gt" / "key.json").read_text())["reference"]["samples"] == 16
    assert REFERENCE == {"samples": 512, "adaptive_threshold": 0.005, "denoise": "NONE"}

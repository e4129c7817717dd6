"""The 36-view renderer on a real procedural bike (bpy module, subprocesses like a user runs them).

Checks docs/contract.md's rig against what Blender actually rendered: keypoints projected with
cameras.json land on the part's mask, the mask is alpha > 0.5, view 0 shows the front wheel on
the left; plus resume after a kill and the bad-input contract.
"""
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from PIL import Image


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PY = sys.executable
SCRIPT = os.path.join(ROOT, "blender_scripts", "render_views.py")
from blender_helpers import _mask, check_keypoints_on_masks  # noqa: E402
from ci_needs import missing  # noqa: E402

FAST = ["--samples", "1", "--denoise", "NONE"]


def run(*args, **kw):
    return subprocess.run([PY, *args], capture_output=True, text=True, cwd=ROOT, **kw)


@pytest.fixture(scope="module")
def bike(tmp_path_factory):
    out = tmp_path_factory.mktemp("lib")
    r = run(os.path.join(ROOT, "blender_scripts", "make_bikes.py"), "--out", str(out), "--count", "1",
            "--seed", "0", "--no-extras")
    assert r.returncode == 0, r.stderr[-2000:]
    bikes = sorted(os.listdir(out / "bikes"))
    return out / "bikes" / bikes[0]


@pytest.fixture(scope="module")
def rendered(bike):
    r = run(SCRIPT, "--bike", str(bike), "--parts", "all", "--views", "0,9,13,22,31", *FAST)
    assert r.returncode == 0, r.stderr[-3000:]
    return bike


def _rgba(views, i):
    return np.asarray(Image.open(views / "rgba" / f"camera{i:04d}" / "0000.png").convert("RGBA"))


@pytest.mark.parametrize("part", ["frame", "steering", "crank", "front_wheel", "rear_wheel", "pedal_left", "pedal_right", "whole"])
def test_keypoints_project_onto_part_masks(rendered, part):
    check_keypoints_on_masks(rendered / "views" / part, [0, 9, 13, 22, 31])


@pytest.mark.parametrize("part", ["frame", "steering", "crank", "front_wheel", "rear_wheel", "pedal_left", "pedal_right", "whole"])
def test_layout_and_mask_is_alpha(rendered, part):
    views = rendered / "views" / part
    cams = json.loads((views / "cameras.json").read_text())
    assert len([k for k in cams if k.startswith("camera")]) == 36
    for i in (0, 9, 13):
        rgba = _rgba(views, i)
        assert rgba.shape == (512, 512, 4)
        m = _mask(views, i)
        assert set(np.unique(m)) <= {0, 255}
        assert np.array_equal(m > 0, rgba[..., 3] / 255.0 > 0.5)
        assert m.any(), f"{part} view {i} is empty"
        jpg = np.asarray(Image.open(views / "img" / f"camera{i:04d}" / "0000.jpg"))
        assert jpg.shape == (512, 512, 3)
        assert jpg[rgba[..., 3] == 0].max() < 40  # RGB on black (JPEG ringing aside)
    tj = json.loads((views / "transforms.json").read_text())
    assert len(tj["frames"]) == 36
    # points.ply holds surface samples of this part near its keypoints' extent
    from plyfile import PlyData

    pts = PlyData.read(str(views / "points.ply"))["vertex"]
    xyz = np.stack([pts["x"], pts["y"], pts["z"]], 1)
    kps = np.array(list(json.loads((views / "keypoints.json").read_text())["keypoints"].values()))
    assert len(xyz) > 1000 and xyz[:, 1].min() > -0.01  # nothing below the ground
    assert np.abs(xyz.mean(0) - kps.mean(0)).max() < 0.6
    orbit = cams["orbit_centre"]
    assert orbit[0] == 0 and orbit[2] == 0
    assert np.isclose(orbit[1], (xyz[:, 1].min() + xyz[:, 1].max()) / 2, atol=0.03)


def test_view0_front_wheel_on_the_left(rendered):
    """Render of the steering part (front wheel) sits left of the frame part (rear wheel) in view 0."""
    kp = json.loads((rendered / "keypoints.json").read_text())["keypoints"]
    assert kp["front_axle"][0] > 0 > kp["rear_axle"][0]
    steer = _mask(rendered / "views" / "steering", 0) > 0
    frame = _mask(rendered / "views" / "frame", 0) > 0
    assert np.nonzero(steer)[1].mean() < np.nonzero(frame)[1].mean()
    # view 9 is from behind: the front wheel is hidden behind the frame, both centred
    steer9 = _mask(rendered / "views" / "steering", 9) > 0
    assert abs(np.nonzero(steer9)[1].mean() - 256) < 30


def test_rerun_skips_finished_views(rendered):
    f = rendered / "views" / "crank" / "rgba" / "camera0000" / "0000.png"
    before = f.stat().st_mtime_ns
    r = run(SCRIPT, "--bike", str(rendered), "--parts", "crank", "--views", "0,9", *FAST)
    assert r.returncode == 0, r.stderr
    assert f.stat().st_mtime_ns == before


def test_kill_and_resume(bike, tmp_path):
    import shutil

    b = tmp_path / "bike"
    shutil.copytree(bike, b, ignore=shutil.ignore_patterns("views"))
    views = list(range(12))
    arg = ",".join(map(str, views))
    # at 128 px: also checks that cameras.json's K follows --size
    cmd = [PY, SCRIPT, "--bike", str(b), "--parts", "frame", "--views", arg, "--size", "128", *FAST]
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT, start_new_session=True)
    rgba_dir = b / "views" / "frame" / "rgba"
    t0 = time.time()
    while time.time() - t0 < 120:
        if rgba_dir.is_dir() and len(list(rgba_dir.glob("*/0000.png"))) >= 3:
            break
        time.sleep(0.05)
    os.killpg(p.pid, signal.SIGKILL)
    p.wait()
    n_before = len(list(rgba_dir.glob("*/0000.png")))
    assert 3 <= n_before < len(views), "the kill should land mid-run"
    # no truncated file under a final name: every finished file decodes
    for f in (b / "views" / "frame").rglob("0000.*"):
        Image.open(f).load()
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    for i in views:
        for kind, ext in (("rgba", "png"), ("img", "jpg"), ("mask", "png")):
            Image.open(b / "views" / "frame" / kind / f"camera{i:04d}" / f"0000.{ext}").load()
    leftovers = [f for f in (b / "views").rglob("*") if f.name.startswith(".")]
    assert not leftovers, leftovers
    check_keypoints_on_masks(b / "views" / "frame", views)


@pytest.mark.parametrize("args, message", [
    (["--bike", "/no/such/bike"], "not found"),
    (["--parts", "wheels"], "unknown part"),
    (["--views", "0,99"], "out of range"),
    (["--views", "a,b"], "comma-separated"),
])
def test_bad_input_one_line_nonzero(bike, args, message):
    full = ["--bike", str(bike)] + args if args[0] != "--bike" else args
    before = sorted(p for p in bike.rglob("*"))
    r = run(SCRIPT, *full)
    assert r.returncode != 0
    err = [l for l in r.stderr.strip().splitlines() if l.strip()]
    assert len(err) == 1 and message in err[0], r.stderr
    assert sorted(p for p in bike.rglob("*")) == before


def test_unreadable_blend(tmp_path):
    b = tmp_path / "broken"
    b.mkdir()
    (b / "bike.blend").write_bytes(b"not a blend file at all")
    (b / "keypoints.json").write_text('{"frame": "canonical", "units": "m", "keypoints": {}}')
    (b / "meta.json").write_text("{}")
    r = run(SCRIPT, "--bike", str(b))
    assert r.returncode != 0
    err = [l for l in r.stderr.strip().splitlines() if l.strip()]
    assert len(err) == 1 and "bike.blend" in err[0], r.stderr
    assert not (b / "views").exists()


def test_help():
    r = run(SCRIPT, "--help")
    assert r.returncode == 0 and "--bike" in r.stdout


@pytest.mark.slow
def test_full_ring_every_part(bike, tmp_path):
    """Every view of every part: keypoints on masks (36 x 4 renders at 1 sample)."""
    import shutil

    b = tmp_path / "bike"
    shutil.copytree(bike, b, ignore=shutil.ignore_patterns("views"))
    r = run(SCRIPT, "--bike", str(b), "--parts", "all", *FAST)
    assert r.returncode == 0, r.stderr[-2000:]
    for part in ("frame", "steering", "crank", "whole"):
        check_keypoints_on_masks(b / "views" / part, range(36))


@pytest.mark.blender_binary
def test_debian_blender_34_renders_views(tmp_path):
    """The same entry points under `blender -b -P` (Debian's 3.4.1, no OIDN): keypoints on masks."""
    import shutil

    blender = shutil.which("blender")
    if blender is None:
        missing("the Debian blender binary")
    for script, args in (("make_bikes.py", ["--out", str(tmp_path), "--count", "1", "--no-extras"]),
                         ("render_views.py", ["--bike", str(tmp_path / "bikes" / "road_00"), "--parts", "steering,crank",
                                              "--views", "0,13", "--samples", "2"])):
        r = subprocess.run([blender, "-b", "-P", os.path.join(ROOT, "blender_scripts", script), "--", *args],
                           capture_output=True, text=True, cwd=str(tmp_path))
        assert r.returncode == 0, (r.stdout[-1500:], r.stderr[-1500:])
    for part in ("steering", "crank"):
        check_keypoints_on_masks(tmp_path / "bikes" / "road_00" / "views" / part, [0, 13])

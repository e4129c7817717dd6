"""Every command, tried with the bad-input families of issue 15 the way a user would type them:
numbers of the right type but an impossible value, output paths that exist as the wrong kind of
thing or cannot be written, views folders whose cameras.json and images disagree, empty config
files, usage errors.  Each must end with a non-zero exit, exactly one line on stderr, no traceback,
and nothing written anywhere under the working folder.

`python -m splatting` commands run in-process through splatting.cli.main (an escaping exception
fails the test); blender_scripts/*.py run as subprocesses with this Python (their checks come
before bpy is imported).
"""
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def snapshot(root):
    out = {}
    for d, dirs, files in os.walk(root):
        for n in dirs + files:
            p = os.path.join(d, n)
            out[os.path.relpath(p, root)] = os.path.getsize(p) if os.path.isfile(p) else -1
    return out


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A working folder with the inputs the bad cases point at."""
    import torch

    from splatting.raster.camera import ring
    from splatting.training.views import write_views

    w = tmp_path_factory.mktemp("bad_input")
    (w / "a_file.txt").write_text("not a folder\n")
    (w / "empty.yaml").write_text("")
    (w / "comments.yaml").write_text("# only a comment\n\n   \n")
    (w / "a_folder").mkdir()
    (w / "a_folder" / "x.txt").write_text("x")
    (w / "mesh.ply").write_text("ply\n")
    cams = [c.scaled(32 / 512) for c in ring(3, orbit_centre=(0.0, 0.5, 0.0))]
    imgs = torch.zeros(3, 32, 32, 4)
    imgs[:, 12:20, 12:20] = 1.0
    for name in ("good", "extra", "missing"):
        write_views(str(w / "bike" / "views" / name), cams, imgs)
    # a rendered view that cameras.json does not list
    extra = w / "bike" / "views" / "extra" / "rgba" / "camera0035"
    extra.mkdir(parents=True)
    (extra / "0000.png").write_bytes((w / "bike" / "views" / "extra" / "rgba" / "camera0000" / "0000.png").read_bytes())
    # a listed camera whose images are gone
    for sub in ("rgba", "img", "mask"):
        d = w / "bike" / "views" / "missing" / sub / "camera0001"
        for f in d.iterdir():
            f.unlink()
        d.rmdir()
    return w


V = "bike/views"
# the good part of each command line; the cases below add one bad value each
TRAIN = ["train", "--views", f"{V}/extra", "--out", "o.ply"]
SHEET = ["contact-sheet", "--bikes", "a_folder", "--out", "s.png"]
RIDER = ["rider", "--id", "m_adult_average_185", "--out", "r.ply"]
AVATAR = ["rider-avatar", "--id", "m_adult_average_185", "--out", "av"]
CYCLIST = ["cyclist", "--rider", "r", "--bike", "a_folder", "--out", "c"]
DATASET = ["dataset", "--preset", "cyclist", "--out", "d"]
DEMO = ["demo", "--out", "dm"]
SPLATTING_CASES = [
    # impossible numbers
    [*TRAIN, "--iterations", "0"],
    [*TRAIN, "--time-budget-s", "-5"],
    [*TRAIN, "--eps2d", "0"],
    [*TRAIN, "--eps2d", "nan"],
    [*TRAIN, "--eps2d", "-0.3"],
    [*TRAIN, "--max-gaussians", "1000000000000"],
    [*TRAIN, "--threads", "0"],
    [*TRAIN, "--holdout", "-1"],
    [*SHEET, "--view", "36"],
    [*SHEET, "--cols", "0"],
    [*SHEET, "--tile", "100000"],
    [*RIDER, "--theta-p-deg", "nan"],
    [*RIDER, "--frame", "-1"],
    [*AVATAR, "--iterations", "-1"],
    [*AVATAR, "--threads", "0"],
    [*AVATAR, "--time-budget-s", "0"],
    [*CYCLIST, "--distance", "-12"],
    [*CYCLIST, "--size", "100000"],
    [*CYCLIST, "--frames", "0"],
    [*CYCLIST, "--elevation", "95"],
    [*CYCLIST, "--fps", "0"],
    [*CYCLIST, "--ik-iterations", "0"],
    [*CYCLIST, "--kp-tolerance=-1,0.1"],
    [*DATASET, "--count", "0"],
    [*DATASET, "--count", "-5"],
    [*DATASET, "--image-size", "100000"],
    [*DATASET, "--workers", "0"],
    [*DATASET, "--seed", "-1"],
    [*DATASET, "--shard", "3/2"],
    [*DATASET, "--shard", "0/0"],
    [*DEMO, "--bikes", "0"],
    [*DEMO, "--train-seconds", "-1"],
    [*DEMO, "--max-gaussians", "0"],
    ["library build", "--out", "lib", "--size", "-64"],
    ["library build", "--out", "lib", "--iterations", "0"],
    ["library build", "--out", "lib", "--workers", "0"],
    ["library build", "--out", "lib", "--gt-poses", "-1"],
    ["library build", "--out", "lib", "--min-iou", "2"],
    ["library build", "--out", "lib", "--posed-poses", "4"],  # 4 are held out: none left to train on
    ["library build", "--out", "lib", "--posed-iterations", "0"],
    ["library build", "--out", "lib", "--recipe", "best"],
    ["library build", "--out", "lib", "--no-posed-train", "--posed-poses", "12"],
    # output paths that exist as a file, or lie under one
    ["train", "--views", f"{V}/good", "--out", "a_folder"],
    ["train", "--views", f"{V}/good", "--out", "a_file.txt/o.ply"],
    ["pose-bike", "--bike", "a_folder", "--pose", "0,0,0,0,0,0,0,0", "--out", "a_folder"],
    ["pose-bike", "--bike", "a_folder", "--pose", "0,0,0,0,0,0,0,0", "--out", "a_file.txt/p.ply"],
    ["contact-sheet", "--bikes", "a_folder", "--out", "a_folder"],
    ["rider", "--id", "m_adult_average_185", "--out", "a_file.txt/r.ply"],
    ["rider-avatar", "--id", "m_adult_average_185", "--out", "a_file.txt"],
    ["cyclist", "--rider", "r", "--bike", "a_folder", "--out", "a_file.txt"],
    ["dataset", "--preset", "cyclist", "--out", "a_file.txt"],
    ["dataset", "--preset", "cyclist", "--out", "a_file.txt/sub"],
    ["dataset merge", "--out", "a_file.txt"],
    ["dataset merge", "--out", "no_such_dataset"],
    ["demo", "--out", "a_file.txt"],
    ["library build", "--out", "a_file.txt"],
    ["bike-posed-train", "--bike", "a_folder"],  # no trained parts
    ["bike-posed-train", "--bike", "a_folder", "--from-rest"],  # no gaussians/frame_rest.ply
    ["bike-posed-train", "--bike", "a_file.txt"],
    # views folders whose cameras.json and images disagree
    ["train", "--views", f"{V}/extra", "--out", "o.ply"],
    ["train", "--views", f"{V}/missing", "--out", "o.ply"],
    ["train", "--views", "a_file.txt", "--out", "o.ply"],
    # empty config files
    ["dataset", "--config", "empty.yaml", "--out", "d"],
    ["dataset", "--config", "comments.yaml", "--out", "d"],
    # usage errors
    ["train"],
    ["no-such-command"],
    ["dataset", "--preset", "cyclist", "--count", "many"],
]


def _argv(case):
    return case[0].split() + case[1:]


@pytest.mark.parametrize("case", SPLATTING_CASES, ids=lambda c: " ".join(c))
def test_splatting_command_refuses(case, work, monkeypatch, capsys):
    from splatting.cli import main

    monkeypatch.chdir(work)
    before = snapshot(work)
    try:
        code = main(_argv(case))
    except SystemExit as e:  # argparse
        code = e.code
    err = capsys.readouterr().err
    assert code not in (0, None), f"exit {code}"
    lines = err.strip("\n").split("\n")
    assert len(lines) == 1 and lines[0].strip(), f"expected one stderr line, got {err!r}"
    assert "Traceback" not in err
    assert "error" in lines[0]
    assert snapshot(work) == before, "a refused command wrote something"


SCRIPT_CASES = [
    ["make_bikes.py", "--out", "a_file.txt"],
    ["make_bikes.py", "--out", "mb", "--count", "-1"],
    ["make_bikes.py", "--out", "mb", "--count", "0", "--no-extras"],
    ["render_views.py", "--bike", "a_folder", "--size", "100000"],
    ["render_views.py", "--bike", "a_folder", "--samples", "0"],
    ["render_views.py", "--bike", "a_folder", "--threads", "0"],
    ["render_views.py", "--bike", "a_file.txt"],
    ["render_pose.py", "--bike", "a_folder", "--pose", "0,0,0,0,0,0,0,0", "--camera", "c.json:camera0000", "--out", "a_folder"],
    ["render_pose.py", "--bike", "a_folder", "--pose", "0,0,0,0,0,0,0,0", "--camera", "c.json:camera0000", "--out", "g.png", "--samples", "-4"],
    ["render_pose.py", "--bike", "a_folder", "--batch", "a_file.txt"],  # not a JSON list of jobs
    ["render_pose.py", "--bike", "a_folder", "--batch", "empty.yaml", "--out", "g.png"],
    ["render_pose.py", "--bike", "a_folder"],  # neither --pose/--camera/--out nor --batch
    ["render_pose.py", "--bike", "a_folder", "--pose", "0,0,0,0,0,0,0,0", "--camera", "c.json:camera0000", "--out", "g.png", "--threads", "0"],
    ["render_rider.py", "--mesh", "mesh.ply", "--out", "a_file.txt"],
    ["render_rider.py", "--mesh", "mesh.ply", "--out", "rv", "--threads", "0"],
    ["import_splats.py", "--ply", "mesh.ply", "--size", "100000"],
    ["import_splats.py", "--ply", "mesh.ply", "--render", "a_folder"],
    ["curate.py", "--input", "mesh.ply", "--out", "a_file.txt"],
    ["curate.py", "--input", "no_model.glb", "--out", "cur"],
    ["build_addon.py", "--out", "a_file.txt"],
    ["add_sub_parts.py", "--bike", "a_file.txt"],
    ["add_sub_parts.py", "--bike", "a_folder", "--gear-ratio", "nan"],
    ["add_sub_parts.py", "--bike", "a_folder", "--gear-ratio", "0"],
    ["add_sub_parts.py", "--bike", "a_folder"],  # not a bike folder: no bike.blend
    ["render_views.py"],
]


@pytest.mark.parametrize("case", SCRIPT_CASES, ids=lambda c: " ".join(c))
def test_blender_script_refuses(case, work):
    before = snapshot(work)
    r = subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", case[0])] + case[1:], cwd=work,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode != 0
    lines = r.stderr.strip("\n").split("\n")
    assert len(lines) == 1 and lines[0].strip(), f"expected one stderr line, got {r.stderr!r}"
    assert "Traceback" not in r.stderr and "error" in lines[0]
    assert snapshot(work) == before, "a refused script wrote something"


def test_checks_accept_good_values(tmp_path, work):
    """The validators must not refuse what is fine (else every case above would pass trivially)."""
    from cyclist_formats import checks

    assert checks.positive("distance", 12.0) == 12.0
    assert checks.image_size("size", 512) == 512
    assert checks.count("count", 1) == 1
    assert checks.output_dir("out", str(tmp_path / "new" / "deeper")) is not None
    assert checks.output_file("out", str(tmp_path / "new" / "x.ply"), (".ply",)) is not None
    (tmp_path / "c.yaml").write_text("count: 3\n")
    assert checks.non_empty_file("config", str(tmp_path / "c.yaml"))
    assert not (tmp_path / "new").exists()  # checks never create anything
    np.testing.assert_equal(checks.index("view", 35, 36), 35)
    assert checks.views_folder(str(work / "bike" / "views" / "good"))

"""`python -m splatting pose-bike` end to end, as a subprocess."""
import json
import math
import os
import subprocess
import sys

import pytest
import torch

from splatting.gaussians.container import read_ply
from helpers import KP, make_bike, ref_part_point

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FIELDS = ["theta_p_deg", "theta_s_deg", "theta_x_deg", "theta_y_deg", "theta_z_deg", "t_x_m", "t_y_m", "t_z_m"]


def cli_inprocess(capsys, *args):
    """The same dispatcher in this process (no torch start-up per call): -> (exit code, stderr)."""
    from splatting.cli import main

    code = main(["pose-bike", *map(str, args)])
    return code, capsys.readouterr().err


def cli(*args):
    env = dict(os.environ, OMP_NUM_THREADS="1")
    return subprocess.run([sys.executable, "-m", "splatting", "pose-bike", *map(str, args)],
                          cwd=ROOT, capture_output=True, text=True, env=env, timeout=120)


@pytest.fixture(scope="module")
def bike(tmp_path_factory):
    return make_bike(tmp_path_factory.mktemp("bikes"), "cli_bike", n=60)


def test_help():
    r = cli("--help")
    assert r.returncode == 0
    assert "--pose" in r.stdout and "--poses" in r.stdout and "--keypoints-out" in r.stdout


def test_single_pose_writes_ply_and_keypoints(bike, tmp_path):
    out, kp = tmp_path / "posed.ply", tmp_path / "kp.json"
    pose = [30, -20, 5, 90, -5, 1.0, 0.1, -2.0]
    r = cli("--bike", bike, f"--pose={','.join(map(str, pose))}", "--out", out, "--keypoints-out", kp,
            "--bike-id", "cli_bike")
    assert r.returncode == 0, r.stderr
    g = read_ply(out)
    canon = [read_ply(os.path.join(bike, "gaussians", p + ".ply")) for p in ("frame", "steering", "crank")]
    assert len(g) == sum(len(c) for c in canon)
    doc = json.loads(kp.read_text())
    assert doc["pose"] == dict(zip(FIELDS, map(float, pose)))
    part_of = {"handle_left": "steering", "handle_right": "steering", "front_axle": "steering",
               "pedal_left": "crank", "pedal_right": "crank"}
    for name, xyz in KP.items():
        want = ref_part_point(part_of.get(name, "frame"), xyz, pose)
        assert max(abs(a - b) for a, b in zip(doc["keypoints"][name], want)) < 1e-6, name
    # the first steering Gaussian sits on front_axle in the synthetic asset
    n0 = len(canon[0])
    assert torch.allclose(g.means[n0], torch.tensor(doc["keypoints"]["front_axle"], dtype=torch.float32), atol=1e-5)
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".")]  # no temp files left


def test_batch_poses_file(bike, tmp_path):
    poses = [[0, 0, 0, 0, 0, 0, 0, 0], dict(zip(FIELDS, [90, 10, 0, 45, 0, 2, 0, 0]))]
    pf = tmp_path / "poses.json"
    pf.write_text(json.dumps(poses))
    out = tmp_path / "batch"
    r = cli("--bike", bike, "--poses", pf, "--out", out)
    assert r.returncode == 0, r.stderr
    assert sorted(os.listdir(out)) == ["pose_00000.json", "pose_00000.ply", "pose_00001.json", "pose_00001.ply"]
    kp1 = json.loads((out / "pose_00001.json").read_text())["keypoints"]
    want = ref_part_point("crank", KP["pedal_right"], [90, 10, 0, 45, 0, 2, 0, 0])
    assert max(abs(a - b) for a, b in zip(kp1["pedal_right"], want)) < 1e-6
    g0 = read_ply(out / "pose_00000.ply")
    frame = read_ply(os.path.join(bike, "gaussians", "frame.ply"))
    assert torch.allclose(g0.means[: len(frame)], frame.means, atol=1e-6)


@pytest.mark.parametrize("case,args,message", [
    ("nan", ["--pose", "0,0,0,nan,0,0,0,0"], "finite"),
    ("inf", ["--pose", "0,0,0,0,0,inf,0,0"], "finite"),
    ("short", ["--pose", "1,2,3"], "8 comma-separated"),
    ("bike_id", ["--pose", "0,0,0,0,0,0,0,0", "--bike-id", "other_bike"], "does not match"),
])
def test_bad_input_one_line_exit_2(bike, tmp_path, capsys, case, args, message):
    out = tmp_path / "x.ply"
    code, err = cli_inprocess(capsys, "--bike", bike, "--out", out, *args)
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1
    assert not os.listdir(tmp_path)  # nothing written, not even a temp file


def test_bad_bike_folders(tmp_path, capsys):
    d = make_bike(tmp_path, "broken", n=20)
    os.remove(os.path.join(d, "gaussians", "crank.ply"))
    code, err = cli_inprocess(capsys, "--bike", d, "--pose", "0,0,0,0,0,0,0,0", "--out", tmp_path / "o.ply")
    assert code == 2 and "crank.ply" in err
    kp = dict(KP, steer_top=KP["steer_bottom"])
    d2 = make_bike(tmp_path, "degenerate", n=20, kp=kp)
    code, err = cli_inprocess(capsys, "--bike", d2, "--pose", "0,0,0,0,0,0,0,0", "--out", tmp_path / "o.ply")
    assert code == 2 and "coincide" in err
    assert not os.path.exists(tmp_path / "o.ply")


def test_bad_poses_file_writes_nothing(bike, tmp_path, capsys):
    pf = tmp_path / "poses.json"
    pf.write_text(json.dumps([[0] * 8, [0, 0, 0, 0, 0, 0, 0, math.inf]]).replace("Infinity", "1e999"))
    out = tmp_path / "batch"
    code, err = cli_inprocess(capsys, "--bike", bike, "--poses", pf, "--out", out)
    assert code == 2 and "pose 1" in err and "finite" in err
    assert not out.exists()
    pf.write_text("[[0,0")
    code, err = cli_inprocess(capsys, "--bike", bike, "--poses", pf, "--out", out)
    assert code == 2 and "not valid JSON" in err
    code, err = cli_inprocess(capsys, "--bike", bike, "--poses", tmp_path / "missing.json", "--out", out)
    assert code == 2 and "no poses file" in err
    assert not out.exists()


def test_bad_input_from_a_real_process(bike, tmp_path):
    r = cli("--bike", bike, "--pose=0,0,0,0,0,0,0,nan", "--out", tmp_path / "x.ply")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "t_z_m" in r.stderr
    assert not os.listdir(tmp_path)


def test_help_field_names_match_the_pose_fields():
    from cyclist_formats.pose import POSE_FIELDS
    from splatting.bike.command import FIELDS_HELP

    assert FIELDS_HELP == ", ".join(POSE_FIELDS) and list(POSE_FIELDS) == FIELDS


def test_batch_chunks_reuse_buffers_without_mixing_poses(bike, tmp_path, capsys, monkeypatch):
    import splatting.bike.command as pb
    from splatting.bike.model import BikeModel

    monkeypatch.setattr(pb, "BATCH_CHUNK", 2)  # 5 poses: chunks of 2, 2 (reusing), 1
    poses = [[10.0 * i, 5.0 * i, 0, 30.0 * i, 0, 0.1 * i, 0, 0] for i in range(5)]
    pf = tmp_path / "poses.json"
    pf.write_text(json.dumps(poses))
    code, err = cli_inprocess(capsys, "--bike", bike, "--poses", pf, "--out", tmp_path / "o")
    assert code == 0, err
    model = BikeModel.load(bike)
    for i, pose in enumerate(poses):
        want = model.pose(pose).gaussians
        got = read_ply(tmp_path / "o" / f"pose_{i:05d}.ply")
        assert torch.allclose(got.means, want.means, atol=1e-6) and torch.allclose(got.sh, want.sh, atol=1e-6), i

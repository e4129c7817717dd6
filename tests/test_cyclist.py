"""`python -m splatting cyclist`: composition, IK in the world, instance masks, keypoint visibility,
the docs/contract.md frame layout, resuming."""
import json
import math
import os

import numpy as np
import pytest
import torch

from helpers import RIDER, write_test_bike

SMPL = ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
        "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
        "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
        "left_hand", "right_hand")
BIKE_KP = ("seat", "steer_top", "steer_bottom", "handle_left", "handle_right", "crank_axle", "pedal_left",
           "pedal_right", "front_axle", "rear_axle", "ground")
PAIRS = ("left_wrist->handle_left", "right_wrist->handle_right", "pelvis->seat", "left_ankle->pedal_left",
         "right_ankle->pedal_right")


@pytest.fixture(scope="module")
def cyclist(tmp_path_factory):
    from splatting.cyclist.assets import load_avatar, load_bike
    from splatting.cyclist.compose import Cyclist
    root = tmp_path_factory.mktemp("bikes")
    bike = load_bike(write_test_bike(str(root)), n_per_part=1500)
    avatar, _ = load_avatar(RIDER, str(root / "none"), n=4000)
    return Cyclist(bike, avatar, ik_iterations=20)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    from splatting.cli import main
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("run")
    write_test_bike(str(root))
    out = str(root / "seq")
    argv = ["cyclist", "--rider", RIDER, "--bike", "city_t", "--bikes-root", str(root), "--riders-root",
            str(root / "none"), "--frames", "3", "--views=0,90,180,-90", "--size", "96", "--out", out, "--ply",
            "--rider-gaussians", "4000", "--ik-iterations", "20", "--steer-range=-15,15", "--global-pose", "0,40,0,0.5,0,-1"]
    assert main(argv) == 0
    return out, argv


def test_orbit_camera_is_the_ring_at_zero_elevation():
    from splatting.raster.camera import ring_camera
    from splatting.cyclist.render import orbit_camera
    for az in (0.0, 10.0, 90.0, -90.0, 180.0, 237.0):
        a, b = orbit_camera(az, 0.0, 12.0, (0.3, 1.0, -0.2)), ring_camera(az, (0.3, 1.0, -0.2))
        assert torch.allclose(a.R, b.R, atol=1e-6) and torch.allclose(a.T, b.T, atol=1e-5)
    c = orbit_camera(0.0, 30.0, 10.0, (0.0, 1.0, 0.0))
    assert c.centre[1] == pytest.approx(1.0 + 10.0 * math.sin(math.radians(30)), abs=1e-4)
    # the orbit centre projects to the image centre
    x = c.R @ torch.tensor([0.0, 1.0, 0.0]) + c.T
    assert float(c.K[0, 0] * x[0] / x[2] + c.K[0, 2]) == pytest.approx(256, abs=1e-3)


def test_rider_sits_on_the_bike_in_the_world(cyclist):
    pose = torch.tensor([[45.0, 20.0, 5.0, 70.0, -3.0, 1.5, 0.1, -2.0]], dtype=torch.float64)
    fr = cyclist.pose(pose)[0]
    j = {n: fr.rider_joints[i] for i, n in enumerate(SMPL)}
    kp = fr.bike_keypoints
    # hands on the posed handles and ankles on the posed pedals, in the world frame (H_g folded in)
    for joint, target in (("left_wrist", "handle_left"), ("right_wrist", "handle_right"),
                          ("left_ankle", "pedal_left"), ("right_ankle", "pedal_right")):
        assert np.linalg.norm(j[joint] - kp[target]) < 0.03, (joint, target)
    assert not any(fr.ik["flagged"].values())
    # the avatar's Gaussians follow the same skeleton: skin lies next to every posed limb end
    rider = fr.gaussians.means[fr.ids == 4].double().numpy()
    for name in ("left_wrist", "right_wrist", "left_ankle", "right_ankle", "head"):
        assert np.linalg.norm(rider - j[name], axis=1).min() < 0.08, name
    assert len(fr.gaussians) == len(fr.ids) == len(cyclist.bike) + len(cyclist.avatar)


def test_instance_masks_have_every_part(cyclist):
    from splatting.cyclist.render import orbit_camera, render_layers
    fr = cyclist.pose(torch.tensor([30.0, 0, 0, 0, 0, 0, 0, 0], dtype=torch.float64))[0]
    centre = fr.gaussians.means.mean(0).tolist()
    L = render_layers(fr.gaussians, fr.ids, orbit_camera(0.0, 10.0, 8.0, centre, 128))
    counts = np.bincount(L["ids"].ravel(), minlength=5)
    assert all(counts[i] > 0 for i in (1, 2, 3, 4)), counts
    assert counts.sum() == 128 * 128
    assert ((L["ids"] > 0) == (L["alpha"] > 0.5)).all()
    # bike-only Gaussians never produce rider pixels
    bike = fr.ids < 4
    Lb = render_layers(fr.gaussians[bike], fr.ids[bike], orbit_camera(0.0, 10.0, 8.0, centre, 128))
    assert (Lb["ids"] != 4).all() and (Lb["ids"] > 0).any()


def test_keypoint_behind_the_rider_is_occluded(cyclist):
    from splatting.cyclist.render import keypoint_visibility, orbit_camera, project_points, render_layers
    fr = cyclist.pose(torch.tensor([0.0, 0, 0, 0, 0, 0, 0, 0], dtype=torch.float64))[0]
    spine = fr.rider_joints[SMPL.index("spine2")]
    cam = orbit_camera(0.0, 0.0, 8.0, spine.tolist(), 128)  # looks along +Z through the torso
    L = render_layers(fr.gaussians, fr.ids, cam)
    pts = np.stack([spine + [0, 0, 0.6],      # behind the torso, seen through it
                    spine - [0, 0, 0.6],      # in front of it
                    spine + [0, 5.0, 0]])     # far above: outside the image
    uv, z = project_points(pts, cam)
    u, v = int(uv[0, 0]), int(uv[0, 1])
    assert L["ids"][v, u] == 4  # the rider is what the camera sees there
    assert keypoint_visibility(uv, z, L["alpha"], L["depth"], 0.1).tolist() == [1, 2, 0]


def test_frame_json_layout_and_outputs(run_dir):
    from PIL import Image
    from splatting.gaussians.container import read_ply
    out, _ = run_dir
    for i in range(3):
        with open(os.path.join(out, f"frame_{i:05d}.json")) as f:
            rec = json.load(f)
        assert rec["frame"] == i and len(rec["pose"]) == 8
        assert rec["pose"][3] == pytest.approx(40.0) and rec["pose"][5] == pytest.approx(0.5)
        assert set(rec["bike_keypoints"]) == set(BIKE_KP)
        assert list(rec["rider_joints"]) == list(SMPL)
        assert all(len(v) == 3 for v in rec["rider_joints"].values())
        assert set(rec["ik"]["residual_m"]) == set(PAIRS) == set(rec["ik"]["flagged"])
        assert all(isinstance(v, bool) for v in rec["ik"]["flagged"].values())
        assert max(rec["ik"]["residual_m"].values()) < 0.05
        g = read_ply(os.path.join(out, "ply", f"{i:05d}.ply"))
        assert len(g) > 4000
    for az in ("0", "90", "180", "-90"):
        d = os.path.join(out, f"view_{az}")
        rgba = np.asarray(Image.open(os.path.join(d, "00001.png")))
        mask = np.asarray(Image.open(os.path.join(d, "00001_mask.png")))
        depth = np.asarray(Image.open(os.path.join(d, "00001_depth.png")))
        assert rgba.shape == (96, 96, 4) and mask.shape == (96, 96)
        assert set(np.unique(mask)) <= {0, 1, 2, 3, 4} and (mask == 4).any() and (mask == 1).any()
        assert ((mask > 0) == (rgba[..., 3] > 127)).mean() > 0.99
        # depth in mm around the 12 m ring distance where the cyclist is
        assert 10000 < np.median(depth[mask > 0]) < 14000 and (depth[rgba[..., 3] == 0] == 0).all()
        with open(os.path.join(d, "00001_keypoints.json")) as f:
            kp = json.load(f)
        assert set(kp["bike"]) == set(BIKE_KP) and list(kp["rider"]) == list(SMPL)
        assert {v[2] for v in kp["rider"].values()} <= {0, 1, 2}
    assert os.path.isfile(os.path.join(out, "preview.png")) and os.path.isfile(os.path.join(out, "preview.gif"))


def test_rerun_skips_finished_frames(run_dir, capsys):
    from splatting.cli import main
    out, argv = run_dir
    before = os.path.getmtime(os.path.join(out, "view_0", "00002.png"))
    os.remove(os.path.join(out, "frame_00001.json"))  # as if killed before frame 1 finished
    assert main(argv) == 0
    assert "2 of 3 frames already done" in capsys.readouterr().out
    assert os.path.getmtime(os.path.join(out, "view_0", "00002.png")) == before
    assert os.path.isfile(os.path.join(out, "frame_00001.json"))


def test_bad_arguments_are_one_line_errors(tmp_path, capsys):
    from splatting.cli import main
    write_test_bike(str(tmp_path))
    base = ["cyclist", "--rider", RIDER, "--bikes-root", str(tmp_path), "--out", str(tmp_path / "o")]
    assert main(base + ["--bike", "nope"]) == 2
    assert main(["cyclist", "--rider", "nobody", "--bike", "city_t", "--bikes-root", str(tmp_path),
                 "--out", str(tmp_path / "o")]) == 2
    assert main(base + ["--bike", "city_t", "--global-pose", "1,2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("splatting cyclist: error:") for line in err)


def test_motion_file_drives_theta_and_ik_start(tmp_path):
    from splatting.cli import main
    write_test_bike(str(tmp_path))
    rng = np.random.default_rng(0)
    pose = (rng.normal(size=(2, 72)) * 0.15).astype(np.float32)
    pose[:, 60:66] = [0.0, 0.0, 0.5, 0.0, 0.0, -0.5]  # wrists bent: the motion's own rotations (SMPL joints 20, 21)
    np.savez(tmp_path / "m.npz", pose=pose, global_t=np.tile([0, 0, 5.0], (2, 1)).astype(np.float32))
    out = tmp_path / "seq"
    assert main(["cyclist", "--rider", RIDER, "--bike", "city_t", "--bikes-root", str(tmp_path), "--riders-root",
                 str(tmp_path / "none"), "--frames", "2", "--views=0", "--size", "48", "--out", str(out),
                 "--motion", str(tmp_path / "m.npz"), "--rider-gaussians", "2000", "--ik-iterations", "20"]) == 0
    recs = [json.load(open(out / f"frame_{i:05d}.json")) for i in range(2)]
    assert recs[0]["source"].endswith("m.npz")
    assert recs[0]["pose"][:2] != recs[1]["pose"][:2]  # theta_p, theta_s follow the motion's frames
    assert all(max(r["ik"]["residual_m"].values()) < 0.05 for r in recs)
    assert main(["cyclist", "--rider", RIDER, "--bike", "city_t", "--bikes-root", str(tmp_path), "--frames", "5",
                 "--out", str(out), "--motion", str(tmp_path / "m.npz")]) == 2  # more frames than the file has

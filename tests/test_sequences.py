"""Street sequences (issue 29): trajectories that obey the kinematic bicycle (rolling without slip,
cadence through the gear, lean from the steady-turn balance, bounded lateral acceleration), the
crossing label at the right frames, stable and unique track ids, the tracking formats' known
answers, and kill-and-resume byte identity."""
import json
import math
import os

import numpy as np
import pytest

from helpers import CITY_KEYPOINTS, kill_and_resume, street_config


def geom():
    from splatting.dataset.sequences.trajectory import bike_geometry
    return bike_geometry(CITY_KEYPOINTS)


def turn(fps=200.0, v=6.0, radius=8.0, n=None):
    from splatting.dataset.sequences import trajectory as tj
    n = n or int(6.0 * fps)
    bumps = [tj.turn_bump(5.0, math.pi / 2, radius)]
    return tj.integrate(n, fps, {"kind": "cruise", "v": v}, bumps, geom(), (1.0, 2.0), -90.0, 2.5, 30.0), fps


# ---------------------------------------------------------------- physics of the trajectories

def test_bike_geometry_of_the_city_bike():
    g = geom()
    kp = CITY_KEYPOINTS
    assert g["L"] == pytest.approx(0.6662 + 0.4584) and g["b"] == pytest.approx(0.4584) and g["r"] == pytest.approx(0.3466)
    # the steering axis (steer_bottom -> steer_top) leans back by atan(dx / dy)
    dx, dy = kp["steer_bottom"][0] - kp["steer_top"][0], kp["steer_top"][1] - kp["steer_bottom"][1]
    assert g["eps"] == pytest.approx(math.atan2(dx, dy))
    ground_x = kp["steer_bottom"][0] + kp["steer_bottom"][1] * dx / dy  # the axis met at Y = 0
    assert g["trail"] == pytest.approx(ground_x - kp["front_axle"][0]) and 0.05 < g["trail"] < 0.12  # ~8 cm


def test_wheels_roll_without_slip_and_pedals_follow_the_gear():
    import torch
    from splatting.bike.pose import posed_bike_keypoints
    from splatting.dataset.sequences.trajectory import poses
    tr, fps = turn()
    P = torch.tensor(poses(tr), dtype=torch.float64)
    kp = posed_bike_keypoints(CITY_KEYPOINTS, P)
    # the rear tyre's contact point (the `ground` keypoint: it stays on the road under any lean)
    ground = kp["ground"].numpy()
    assert np.abs(ground[:, 1]).max() < 1e-9
    vel = (ground[2:, [0, 2]] - ground[:-2, [0, 2]]) * fps / 2
    yaw = np.radians(tr["theta_y_deg"][1:-1])
    fwd, side = np.stack([np.cos(yaw), -np.sin(yaw)], 1), np.stack([np.sin(yaw), np.cos(yaw)], 1)
    # rolling without slip: the contact point advances by wheel rate x radius (its material point
    # is at rest on the road), and it does not slide sideways
    slip = np.sum(vel * fwd, 1) - tr["wheel_rate"][1:-1] * geom()["r"]
    assert np.abs(slip).max() < 1e-3 * 6.0
    assert np.abs(np.sum(vel * side, 1)).max() < 1e-3 * 6.0
    # the wheel angle advances by s / r between frames
    assert np.allclose(np.diff(tr["wheel_rad"]) * geom()["r"], np.diff(tr["s"]))
    # the pedal's angle about the crank axle advances at wheel rate / gear ratio (forward = clockwise about +Z)
    ped = kp["pedal_left"].numpy() - kp["crank_axle"].numpy()
    yaw = np.radians(tr["theta_y_deg"])
    fwd = np.stack([np.cos(yaw), np.zeros_like(yaw), -np.sin(yaw)], 1)
    crank = kp["crank_axle"].numpy()
    up = crank - np.column_stack([tr["origin_xz"][:, 0], np.zeros(len(crank)), tr["origin_xz"][:, 1]])
    up /= np.linalg.norm(up, axis=1, keepdims=True)  # the leaned frame's up: the crank axle is above the origin
    ang = np.unwrap(np.arctan2(np.sum(ped * fwd, 1), np.sum(ped * up, 1)))  # from up towards forward: + pedalling
    rate = np.diff(ang) * fps
    expect = 0.5 * (tr["wheel_rate"][1:] + tr["wheel_rate"][:-1]) / 2.5
    assert np.allclose(rate, expect, rtol=0.02, atol=0.02)


def test_lean_matches_the_steady_turn_and_steering_the_path():
    tr, fps = turn(v=6.0, radius=8.0)
    g = geom()
    # curvature measured from the rear contact point's path, independent of the model's kappa
    rear = tr["rear_xz"]
    d1 = np.gradient(rear, axis=0) * fps
    d2 = np.gradient(d1, axis=0) * fps
    kap = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3
    kap = -kap  # theta_Y grows to the left: forward (cos, -sin) turns towards -Z
    i = int(np.argmax(np.abs(tr["kappa"])))
    assert abs(kap[i]) == pytest.approx(1 / 8.0, rel=0.01)  # the tightest radius is the asked one
    v = tr["speed"][i]
    assert -tr["theta_x_deg"][i] == pytest.approx(math.degrees(math.atan(v * v * kap[i] / 9.81)), abs=0.2)
    assert tr["theta_x_deg"][i] < 0  # a left turn leans to the rider's left (canonical -Z)
    # ground steer angle from the pose's theta_s about the raked axis: tan(delta) = tan(theta_s) cos(eps)
    delta = math.atan(math.tan(math.radians(tr["theta_s_deg"][i])) * math.cos(g["eps"]))
    assert delta == pytest.approx(math.atan(g["L"] * kap[i]), rel=0.02)
    # the heading turned by 90 degrees and is the rear path's tangent
    assert tr["theta_y_deg"][-1] - tr["theta_y_deg"][0] == pytest.approx(90.0, abs=0.05)
    tang = np.degrees(np.arctan2(-d1[:, 1], d1[:, 0]))
    assert np.allclose(((tang - tr["theta_y_deg"] + 180) % 360) - 180, 0, atol=0.2)


def test_lateral_acceleration_bounded_and_stop_start_speeds(bikes):
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.sequences.draw import draw_sequence
    cfg = resolve_assets(validate(street_config(bikes, count=1, sequence={"enabled": True, "length": 80, "fps": 10.0,
                                                                        "max_lateral_accel_mps2": 2.0},
                                                street={"cyclists": [4, 4], "parked_bikes": [0, 0]})))
    seen = set()
    for seq in range(12):
        for inst in draw_sequence(cfg, seq)["instances"]:
            tr, man = inst["traj"], inst["manoeuvre"]
            seen.add(man)
            # from the positions (the rear contact point), not from the model's kappa
            rear = tr["rear_xz"]
            vel = np.gradient(rear, axis=0) * 10.0
            acc = np.gradient(vel, axis=0) * 10.0
            sp = np.linalg.norm(vel, axis=1)
            lat = np.abs(vel[:, 0] * acc[:, 1] - vel[:, 1] * acc[:, 0]) / np.maximum(sp, 1e-6)
            assert lat[2:-2].max() < 2.0 * 1.1, (man, lat.max())
            assert 2.0 - 1e-9 <= tr["speed"].max() <= 8.0 + 1e-9
            if man == "stop":
                assert tr["speed"][-1] < 1e-6 and not tr["pedalling"][-1]
                braking = tr["accel"] < -0.05
                assert braking.any() and np.all(tr["crank_rate"][braking] == 0)  # coasting while braking
            if man == "start":
                assert tr["speed"][0] == 0 and tr["speed"][-1] > 1.0
    assert seen == {"straight", "turn_left", "turn_right", "cross", "overtake", "stop", "start", "swerve"}


# ---------------------------------------------------------------- intention

def test_crossing_label_known_answer():
    from splatting.dataset.sequences.trajectory import crossing_frames
    x = [4.0, 4.0, 3.9, 3.0, 1.0, -1.0, -1.6, -3.0]
    # theta_Y -90 rides along +Z; -120 .. -170 points towards -X (the camera's path at X = 0)
    heading = [-90, -90, -120, -150, -170, -170, -170, -170]
    assert crossing_frames(x, heading, 1.5).tolist() == [False, False, True, True, True, True, False, False]
    # riding along the road beside the lane never crosses; heading away from the path neither
    assert not crossing_frames([4.0] * 5, [-90] * 5, 1.5).any()
    assert not crossing_frames([4.0, 4.5, 5.0], [-60, -60, -60], 1.5).any()
    # from the other side (X < 0) towards +X
    assert crossing_frames([-3.0, -2.0, 0.0, 2.0], [-45, -45, -45, -45], 1.5).tolist() == [True, True, True, False]
    # an overtake's lane change towards the path and back, never reaching the lane: no crossing
    x = [5.0, 4.8, 4.2, 3.6, 3.3, 3.4, 3.9, 4.5]
    heading = [-90, -105, -115, -110, -95, -75, -70, -85]
    assert not crossing_frames(x, heading, 1.5).any()
    # ... but one that reaches the lane is, from its turn on
    assert crossing_frames([5.0, 4.0, 2.5, 1.2, 0.0, -2.0], [-90, -120, -130, -130, -100, -90], 1.5).tolist() == \
        [False, True, True, True, True, False]


def test_a_drawn_crossing_is_labelled_from_the_turn_until_past_the_lane(bikes):
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.sequences.draw import draw_sequence
    only = {m: 0.0 for m in ("straight", "turn_left", "turn_right", "overtake", "stop", "start", "swerve")}
    cfg = resolve_assets(validate(street_config(bikes, count=1, sequence={
        "enabled": True, "length": 60, "fps": 10.0, "manoeuvres": dict(only, cross=1.0)},
        street={"cyclists": [1, 1], "parked_bikes": [0, 0]})))
    for seq in range(4):
        inst = draw_sequence(cfg, seq)["instances"][0]
        x = inst["traj"]["origin_xz"][:, 0]
        side = math.copysign(1, x[0])
        towards = -side * np.cos(np.radians(inst["traj"]["theta_y_deg"]))  # lateral direction component
        first = int(np.argmax(towards >= math.sin(math.radians(10))))
        past = np.flatnonzero(x * side < -1.5)
        last = int(past[0]) if len(past) else len(x)
        expect = np.zeros(len(x), bool)
        expect[first:last] = True
        assert inst["crossing"].tolist() == expect.tolist()
        assert inst["crossing"].any() and [lab == "crossing" for lab in inst["intention"]] == expect.tolist()


# ---------------------------------------------------------------- formats: known answers

OBJ = {"type": "Cyclist", "truncated": 0.3, "occluded": 1, "alpha": -1.2345, "x1": 100.0, "y1": 50.5, "x2": 140.25,
       "y2": 120.0, "h": 1.8, "w": 0.6, "l": 1.9, "x": 2.5, "y": 1.65, "z": 12.0, "rotation_y": 1.5708}


def test_kitti_tracking_known_answer():
    from splatting.dataset.sequences.writers import kitti_tracking_text
    text = kitti_tracking_text([(0, [[1, OBJ], [3, dict(OBJ, truncated=0.0, type="Misc")]]),
                                (1, [[1, dict(OBJ, truncated=0.7, occluded=2, z=11.5)]])])
    assert text == ("0 1 Cyclist 1 1 -1.23 100.00 50.50 140.25 120.00 1.80 0.60 1.90 2.50 1.65 12.00 1.57\n"
                    "0 3 Misc 0 1 -1.23 100.00 50.50 140.25 120.00 1.80 0.60 1.90 2.50 1.65 12.00 1.57\n"
                    "1 1 Cyclist 2 2 -1.23 100.00 50.50 140.25 120.00 1.80 0.60 1.90 2.50 1.65 11.50 1.57\n")
    assert all(len(line.split()) == 17 for line in text.splitlines())


def test_mot_known_answer():
    from splatting.dataset.sequences.writers import mot_gt_text, seqinfo_text
    rows = [(0, [[2, {"box": [10.0, 20.0, 30.5, 40.0], "kind": "parked", "visibility": 0.5}],
                 [1, {"box": [1.0, 2.0, 3.0, 4.0], "kind": "cyclist", "visibility": 1.0}]]),
            (1, [[1, {"box": [1.5, 2.0, 3.0, 4.0], "kind": "cyclist", "visibility": 0.25}]])]
    assert mot_gt_text(rows) == ("1,1,1.00,2.00,3.00,4.00,1,1,1.0000\n"
                                 "1,2,10.00,20.00,30.50,40.00,1,4,0.5000\n"
                                 "2,1,1.50,2.00,3.00,4.00,1,1,0.2500\n")
    assert seqinfo_text("0003", 10.0, 100, 1600, 900) == (
        "[Sequence]\nname=0003\nimDir=img1\nframeRate=10\nseqLength=100\nimWidth=1600\nimHeight=900\nimExt=.png\n")


def test_coco_video_known_answer():
    from splatting.dataset.sequences.writers import coco_video
    ims = [({"id": 1, "file_name": "0000/000000.png"}, 1, 0), ({"id": 2, "file_name": "0000/000001.png"}, 1, 1)]
    anns = [{"track_id": 1, "instance_id": 13, "video_id": 1, "category_id": 3},
            {"track_id": 1, "instance_id": 11, "video_id": 1, "category_id": 1},
            {"track_id": 1, "instance_id": 13, "video_id": 1, "category_id": 3}]
    images, tracks = coco_video(ims, anns, [])
    assert images[1] == {"id": 2, "file_name": "0000/000001.png", "video_id": 1, "frame_id": 1, "frame_index": 1}
    assert tracks == [{"id": 11, "track_id": 1, "video_id": 1, "category_id": 1},
                      {"id": 13, "track_id": 1, "video_id": 1, "category_id": 3}]


# ---------------------------------------------------------------- config errors

@pytest.mark.parametrize("over, field", [
    ({"sequence": {"enabled": True, "length": 1}}, "sequence.length"),
    ({"sequence": {"enabled": True, "fps": float("nan")}}, "sequence.fps"),
    ({"sequence": {"enabled": True, "manoeuvres": {"cross": 0, "straight": 0, "turn_left": 0, "turn_right": 0,
                                                   "overtake": 0, "stop": 0, "start": 0, "swerve": 0}}},
     "sequence.manoeuvres"),
    ({"sequence": {"enabled": True, "ego": {"motion": "flying"}}}, "sequence.ego.motion"),
    ({"labels": {"formats": ["mot"]}}, "labels.formats"),
    ({"sequence": {"enabled": True}, "lighting": {"mode": "relit"}}, "lighting.mode"),
])
def test_bad_sequence_configs_name_their_field(bikes, over, field):
    from cyclist_formats.errors import UserError
    from splatting.dataset.config import validate
    with pytest.raises(UserError, match=f"'{field}'"):
        validate(street_config(bikes, **over))


def test_mode_must_be_street(bikes):
    from cyclist_formats.errors import UserError
    from helpers import small_config
    from splatting.dataset.config import validate
    with pytest.raises(UserError, match="sequence.enabled"):
        validate(small_config(bikes, sequence={"enabled": True}))


# ---------------------------------------------------------------- rendered sequences

def seq_config(bikes, **kw):
    only = {m: 0.0 for m in ("straight", "turn_left", "turn_right", "overtake", "stop", "start", "swerve")}
    return street_config(bikes, count=1, labels={"formats": ["coco", "kitti", "mot"]},
                         sequence={"enabled": True, "length": 3, "fps": 10.0, "manoeuvres": dict(only, cross=1.0, turn_left=1.0)},
                         street={"cyclists": [2, 2], "parked_bikes": [1, 1], "distance_m": [6, 12]},
                         appearance={"enabled": True}, **kw)


def read(path):
    with open(path, "rb") as f:
        return f.read()


def test_sequence_tracks_formats_and_resume(bikes, tmp_path):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    cfg = validate(seq_config(bikes))
    a, b = str(tmp_path / "a"), str(tmp_path / "b")
    generate(cfg, a, log=lambda m: None, progress=False)
    with open(os.path.join(a, "annotations.json")) as f:
        doc = json.load(f)
    assert doc["videos"] == [{"id": 1, "name": "0000", "width": 621, "height": 188, "length": 3, "fps": 10.0}]
    assert [(im["video_id"], im["frame_id"], im["file_name"]) for im in doc["images"]] == [
        (1, f, f"0000/{f:06d}.png") for f in range(3)]
    # track ids: each instance keeps its id through the frames, ids differ between instances
    by_track = {}
    for ann in doc["annotations"]:
        by_track.setdefault(ann["track_id"], set()).add((ann["bike"], ann["rider"], ann["manoeuvre"], ann["instance"]))
    assert all(len(v) == 1 for v in by_track.values()) and len(by_track) >= 2
    recs = [[(i["track_id"], i["bike"], i["rider"], i["manoeuvre"]) for i in im["instances"]] for im in doc["images"]]
    assert recs[0] == recs[1] == recs[2] and [t[0] for t in recs[0]] == [1, 2, 3]  # 2 cyclists + 1 parked bike
    assert set(by_track) <= {1, 2, 3}
    # the parked bike stands still; a cyclist moves by its velocity between frames
    for ann in doc["annotations"]:
        assert ann["video_id"] == 1 and (ann["speed_mps"] == 0) == ann["parked"]
    cyc = [x for x in doc["annotations"] if x["category_id"] == 3 and x["track_id"] == 1]
    if len(cyc) == 3:
        p0, p1 = (np.array(c["pose_3d"]["bottom_centre_world_m"]) for c in cyc[:2])
        v = np.array(cyc[0]["velocity_world_mps"])
        assert np.linalg.norm((p1 - p0) - v * 0.1) < 0.05 * max(np.linalg.norm(v * 0.1), 0.1) + 0.03
    # the tracking files: every frame's ids the COCO track ids; one calib and seqinfo per sequence
    kit = read(os.path.join(a, "kitti_tracking", "training", "label_02", "0000.txt")).decode().splitlines()
    assert kit and all(len(line.split()) == 17 for line in kit)
    assert {int(line.split()[1]) for line in kit} <= {1, 2, 3}
    assert sorted({int(line.split()[0]) for line in kit}) == [0, 1, 2]
    gt = read(os.path.join(a, "mot", "0000", "gt", "gt.txt")).decode().splitlines()
    assert {int(line.split(",")[0]) for line in gt} == {1, 2, 3}
    for line in gt:
        fr, tid = int(line.split(",")[0]), int(line.split(",")[1])
        ann = [x for x in doc["annotations"] if x["frame_id"] == fr - 1 and x["track_id"] == tid
               and x["category_id"] in (3, 1) and (x["category_id"] == 1) == x["parked"]][0]
        assert [float(v) for v in line.split(",")[2:6]] == pytest.approx(ann["bbox_amodal"], abs=0.006)
    assert os.path.isfile(os.path.join(a, "mot", "0000", "img1", "000003.png"))
    assert read(os.path.join(a, "kitti_tracking", "training", "image_02", "0000", "000002.png")) == \
        read(os.path.join(a, "images", "0000", "000002.png"))
    # a killed run: a frame's shard and image gone, a half-assembled sequence's text files gone
    kill_and_resume(generate, cfg, a, b, ["shards/0000/000001.json", "images/0000/000002.png", "annotations.json",
                                          "mot/0000/gt/gt.txt", "kitti_tracking/training/label_02/0000.txt"],
                    ["annotations.json", "images/0000/000001.png", "images/0000/000002.png", "mot/0000/gt/gt.txt",
                     "mot/0000/seqinfo.ini", "kitti_tracking/training/label_02/0000.txt",
                     "kitti_tracking/training/calib/0000.txt", "shards/0000/000001.json"], generated=2)


def test_preset_and_command_line(tmp_path):
    import subprocess
    import sys
    from helpers import ROOT
    from splatting.dataset.config import load_config
    c = load_config(preset="street-sequence")
    assert c.sequence.enabled and (c.sequence.length, c.sequence.fps) == (100, 10)
    assert c.labels.formats == ["coco", "kitti", "mot"] and c.camera.preset == "nuscenes"
    # MOT on a still set: one line naming the field, non-zero, nothing written
    out = tmp_path / "o"
    r = subprocess.run([sys.executable, "-m", "splatting", "dataset", "--preset", "street", "--format", "mot",
                        "--out", str(out)], cwd=ROOT, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=ROOT))
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1 and "labels.formats" in r.stderr
    assert not out.exists()


def test_sharded_sequence_frames_merge_to_the_same_bytes(bikes, tmp_path):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from splatting.dataset.merge import merge_dataset
    cfg = validate(seq_config(bikes, seed=11))
    a, b = str(tmp_path / "a"), str(tmp_path / "b")
    generate(cfg, a, log=lambda m: None, progress=False)
    r0 = generate(cfg, b, log=lambda m: None, progress=False, shard=(0, 2))  # frames 0 and 2
    assert r0["annotations"] is None and not os.path.exists(os.path.join(b, "annotations.json"))
    from cyclist_formats.errors import UserError
    with pytest.raises(UserError, match="1 of 3 samples"):  # frame 1 missing: merge refuses
        merge_dataset(b)
    generate(cfg, b, log=lambda m: None, progress=False, shard=(1, 2))
    merge_dataset(b)
    for rel in ("annotations.json", "mot/0000/gt/gt.txt", "kitti_tracking/training/label_02/0000.txt"):
        assert read(os.path.join(a, rel)) == read(os.path.join(b, rel)), rel


def test_ego_camera_moves_along_the_road_or_stands(bikes):
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.sequences.draw import draw_sequence, ego_camera
    for motion in ("moving", "static"):
        cfg = resolve_assets(validate(street_config(bikes, count=1, sequence={
            "enabled": True, "length": 11, "fps": 10.0, "ego": {"motion": motion, "speed_mps": [5.0, 6.0]}})))
        sd = draw_sequence(cfg, 0)
        centres = []
        for f in (0, 10):
            cam = ego_camera(sd, f)
            R, T = cam.R.double().numpy(), cam.T.double().numpy()
            centres.append(-R.T @ T)
        moved = centres[1] - centres[0]
        if motion == "static":
            assert np.allclose(moved, 0) and sd["ego_speed"] == 0
        else:  # 1 s of driving along +Z at the drawn speed, at the preset's height
            assert 5.0 <= sd["ego_speed"] <= 6.0
            assert np.allclose(moved, [0, 0, sd["ego_speed"]], atol=1e-5)
        assert centres[0][1] == pytest.approx(1.65, abs=1e-6)

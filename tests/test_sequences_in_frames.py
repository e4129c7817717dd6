"""Sequences in real KITTI frames (issue 29 on issue 26's frames): the frame stands still as the
world, cyclists ride through it kept off the labelled boxes and the LiDAR's obstacles along their
whole paths, hidden by the frame's depth in every frame, written as KITTI tracking (the frame's own
objects as static tracks), MOT and COCO-video, resumable byte for byte.  A synthetic KITTI frame
stands in for KITTI's data (tests/kitti_synth.py); the development frames' test skips when
../shared/realism/kitti_dev is absent."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import kitti_synth as ks
from helpers import RIDER, kill_and_resume, resolved, small_config, with_blocks

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEV = next((p for p in (os.path.join(ROOT, "..", "shared", "realism", "kitti_dev"),
                        os.path.join(ROOT, "..", "..", "shared", "realism", "kitti_dev")) if os.path.isdir(p)), "")
DONTCARE = "DontCare -1 -1 -10 5.00 29.89 24.12 67.61 -1 -1 -1 -1000 -1000 -1000 -10"
ONLY = ("straight", "turn_left", "turn_right", "cross", "overtake", "stop", "start", "swerve")


def seq_config(bikes, frames, length=3, manoeuvres=None, **kw):
    cfg = small_config(bikes, mode="frames", frames=frames, count=2, labels={"formats": ["coco", "kitti", "mot"]},
                       street={"cyclists": [2, 2], "parked_bikes": [0, 1], "distance_m": [5, 25], "lateral_m": [-8, 8]},
                       sequence={"enabled": True, "length": length, "fps": 10.0, "ego": {"motion": "static"},
                                 **({"manoeuvres": manoeuvres} if manoeuvres else {})})
    cfg.pop("image_size")
    return with_blocks(cfg, **kw)


def read(path):
    with open(path, "rb") as f:
        return f.read()


def test_config_frames_sequence_needs_a_standing_camera_and_the_preset_loads(bikes, tmp_path):
    from cyclist_formats.errors import UserError
    from splatting.dataset.config import load_config, validate
    root = ks.write_frames(str(tmp_path / "f"), {"000000": []})
    with pytest.raises(UserError, match="'sequence.ego.motion'.*stands still"):
        validate(seq_config(bikes, root, sequence={"ego": {"motion": "moving"}}))
    c = load_config(preset="kitti-sequence")
    assert c.mode == "frames" and c.sequence.enabled and c.sequence.ego.motion == "static"
    assert list(c.labels.formats) == ["coco", "kitti", "mot"]


def test_tracks_stay_off_labelled_boxes_at_every_frame(bikes, tmp_path):
    from splatting.dataset.sequences.draw import draw_sequence
    cars = [ks.box_row("Car", 1.5, 1.7, 4.2, x, 1.65, z, ry) for x, z, ry in
            ((-3.0, 12.0, 1.57), (2.5, 9.0, 1.5), (0.0, 20.0, -1.6), (-1.5, 28.0, 1.6), (3.5, 16.0, 0.1))]
    root = ks.write_frames(str(tmp_path / "f"), {"000000": cars})
    cfg = resolved(seq_config(bikes, root, length=40, street={"cyclists": [3, 3], "parked_bikes": [1, 1]}))
    n_tracks = 0
    for seq in range(4):
        for inst in draw_sequence(cfg, seq)["instances"]:
            n_tracks += 1
            for p in inst["poses"]:  # world X is rect -x, Z rect z on this level road
                x, z = -p[5], p[7]
                for c in cars:
                    h, w, l, bx, by, bz, ry = (float(v) for v in c.split()[8:15])
                    dx, dz = x - bx, z - bz
                    lx, lz = dx * np.cos(ry) - dz * np.sin(ry), dx * np.sin(ry) + dz * np.cos(ry)
                    assert abs(lx) > l / 2 + 0.5 or abs(lz) > w / 2 + 0.5, (inst["manoeuvre"], p, c)
    assert n_tracks >= 8


def test_tracks_never_ride_through_an_unlabelled_wall(bikes, tmp_path):
    from splatting.dataset.sequences.draw import draw_sequence
    root = ks.write_frames(str(tmp_path / "f"), {"000000": []}, with_velodyne=True)
    scan, end = ks.scan_with_wall(15.0, 1.0)
    scan.tofile(os.path.join(root, "velodyne", "000000.bin"))
    man = dict({m: 0.0 for m in ONLY}, straight=1.0)
    crossed = {}
    for use in (True, False):
        # 1.9 s at 3-5 m/s: a track reaches 2.9-4.8 m either side of its middle spot (4-30 m away)
        cfg = resolved(seq_config(bikes, root, length=20, manoeuvres=man, insert={"lidar": use},
                                  street={"cyclists": [3, 3], "parked_bikes": [0, 0], "distance_m": [4, 30],
                                          "lateral_m": [-6, 6], "max_tries": 200},
                                  sequence={"speed_mps": [3.0, 5.0]}))
        zs = [inst["poses"][:, 7] for seq in range(6) for inst in draw_sequence(cfg, seq)["instances"]]
        assert len(zs) >= 6
        crossed[use] = sum(bool((z.min() < 15.0 + 1.0) and (z.max() > 15.0 - 1.0)) for z in zs)
    assert crossed[True] == 0  # no footprint (0.95 m half-length) ever reaches the wall at Z = 15
    assert crossed[False] >= 2  # without the scan nothing knows it is there: tracks ride through it


def test_a_car_in_front_hides_the_cyclist_in_every_frame(bikes, tmp_path):
    from splatting.dataset.generate import Assets
    from splatting.dataset.labels import CATEGORY_IDS
    from splatting.dataset.sequences.render import make_frame
    car = ks.box_row("Car", 1.5, 1.8, 4.2, 0.0, 1.65, 6.0, 0.0)  # across the road: x -2.1..2.1, z 5.1..6.9
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [car]})
    man = dict({m: 0.0 for m in ONLY}, straight=1.0)
    cfg = resolved(seq_config(bikes, root, length=4, manoeuvres=man, backgrounds={"shadow": False},
                              insert={"look": {"match": False}},
                              street={"cyclists": [1, 1], "parked_bikes": [0, 0], "distance_m": [8.5, 10],
                                      "lateral_m": [-0.5, 0.5], "oncoming_share": 0.0,
                                      "max_tries": 400}))
    assets = Assets(cfg)
    for f in range(4):
        rgb, image, anns, rows = make_frame(cfg, f, assets)
        assert len(image["instances"]) == 1 and image["background"]["look"]["hidden_px"] > 0
        cyc = next(a for a in anns if a["category_id"] == CATEGORY_IDS["cyclist"])
        assert cyc["occlusion"] >= 1 and cyc["visibility"] < 0.7
        kit = dict((t, o) for t, o in rows["kitti"])
        assert kit[1]["type"] == "Cyclist" and kit[1]["occluded"] >= 1
        assert kit[2]["type"] == "Car" and kit[2]["occluded"] == 0  # the car in front is not covered


def test_a_pedestrian_behind_the_cyclist_is_raised_to_occluded_in_every_frame(bikes, tmp_path):
    from splatting.dataset.generate import Assets
    from splatting.dataset.sequences.render import make_frame
    ped = ks.box_row("Pedestrian", 1.75, 0.6, 0.8, 0.2, 1.65, 16.0, 1.57)  # 16 m ahead, just right of the axis
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [ped]})
    man = dict({m: 0.0 for m in ONLY}, straight=1.0)
    cfg = resolved(seq_config(bikes, root, length=4, manoeuvres=man, backgrounds={"shadow": False},
                              street={"cyclists": [1, 1], "parked_bikes": [0, 0], "distance_m": [7, 8],
                                      "lateral_m": [-0.4, 0.0], "oncoming_share": 0.0, "max_tries": 400},
                              sequence={"speed_mps": [2.0, 2.5]}))
    assets = Assets(cfg)
    for f in range(4):
        _, image, _, rows = make_frame(cfg, f, assets)
        assert len(image["instances"]) == 1
        kit = dict((t, o) for t, o in rows["kitti"])
        assert kit[2]["type"] == "Pedestrian" and kit[2]["occluded"] >= 1  # was 0 in the frame's label
        assert image["frame"]["occlusion_raised"][0][:2] == [0, kit[2]["occluded"]]


def test_formats_static_tracks_and_resume_byte_identical(bikes, tmp_path):
    from cyclist_formats.kitti_frame import read_velodyne
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    car = ks.box_row("Car", 1.5, 1.7, 4.2, -3.0, 1.65, 12.0, 1.57)
    ped = ks.box_row("Pedestrian", 1.75, 0.6, 0.8, 2.0, 1.65, 15.0, 1.57, occluded=1)
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [car, ped, DONTCARE], "000001": [car]}, with_velodyne=True)
    cfg = validate(seq_config(bikes, root))
    a, b = str(tmp_path / "a"), str(tmp_path / "b")
    generate(cfg, a, log=lambda m: None, progress=False)
    with open(os.path.join(a, "annotations.json")) as f:
        doc = json.load(f)
    assert [v["name"] for v in doc["videos"]] == ["0000", "0001"]
    assert [im["frame"]["frame"] for im in doc["images"]] == ["000000"] * 3 + ["000001"] * 3
    assert all(im["sequence"]["ego_speed_mps"] == 0 for im in doc["images"])
    # one light gain per sequence (measured around all its tracks): no flicker as the cyclists move
    gains = [[im["background"]["look"]["gain"] for im in doc["images"] if im["video_id"] == v] for v in (1, 2)]
    assert all(len({tuple(g) for g in gs}) == 1 for gs in gains) and gains[0][0] != [1.0, 1.0, 1.0]
    kt = os.path.join(a, "kitti_tracking", "training")
    for s, fid, own in ((0, "000000", [car, ped, DONTCARE]), (1, "000001", [car])):
        n_ins = len(doc["images"][3 * s]["instances"])
        assert n_ins >= 2
        lines = read(os.path.join(kt, "label_02", f"{s:04d}.txt")).decode().splitlines()
        assert all(len(x.split()) == 17 for x in lines)
        for f in range(3):
            rows = [x.split() for x in lines if int(x.split()[0]) == f]
            assert [int(r[1]) for r in rows[:n_ins]] == list(range(1, n_ins + 1))  # the inserted tracks first
            frame_rows = rows[n_ins:]  # then the frame's own objects, ids after them (DontCare: -1)
            assert [r[2] for r in frame_rows] == [o.split()[0] for o in own]
            want = [n_ins + 1 + k if o.split()[0] != "DontCare" else -1 for k, o in enumerate(own)]
            assert [int(r[1]) for r in frame_rows] == want
            for r, o in zip(frame_rows, own):  # every field kept but truncation (an integer level) and occluded
                src = o.split()
                assert r[6:] == [f"{float(v):.2f}" for v in src[4:]]
                assert int(r[4]) >= int(src[2])  # occlusion raised or kept, never lowered
                assert r[3] == ("-1" if src[0] == "DontCare" else "0")
        # the frame's calib byte for byte; its scan with the cyclists in it, per frame
        assert read(os.path.join(kt, "calib", f"{s:04d}.txt")) == read(os.path.join(root, "calib", fid + ".txt"))
        src = read_velodyne(os.path.join(root, "velodyne", fid + ".bin"))
        scans = [read_velodyne(os.path.join(kt, "velodyne", f"{s:04d}", f"{f:06d}.bin")) for f in range(3)]
        assert all(not np.array_equal(x, src) for x in scans)
        gt = read(os.path.join(a, "mot", f"{s:04d}", "gt", "gt.txt")).decode().splitlines()
        car_rows = [x.split(",") for x in gt if int(x.split(",")[1]) == n_ins + 1]
        assert len(car_rows) == 3 and all(r[7] == "3" and r[8] == "-1.0000" for r in car_rows)
        assert [float(v) for v in car_rows[0][2:6]] == pytest.approx(
            [float(v) for v in (car.split()[4], car.split()[5])] +
            [float(car.split()[6]) - float(car.split()[4]), float(car.split()[7]) - float(car.split()[5])], abs=0.006)
    # kill and resume: a shard, an image, a scan and the assembled files gone
    kill_and_resume(generate, cfg, a, b, ["shards/0001/000001.json", "images/0000/000002.png", "annotations.json",
                                          "mot/0001/gt/gt.txt", "kitti_tracking/training/label_02/0000.txt",
                                          "kitti_tracking/training/calib/0001.txt"],
                    ["annotations.json", "images/0000/000002.png", "images/0001/000001.png", "mot/0001/gt/gt.txt",
                     "kitti_tracking/training/label_02/0000.txt", "kitti_tracking/training/calib/0001.txt",
                     "kitti_tracking/training/velodyne/0001/000001.bin", "shards/0001/000001.json"], generated=2)


def test_command_refuses_a_moving_camera_and_a_missing_folder_in_one_line(bikes, tmp_path):
    import yaml
    root = ks.write_frames(str(tmp_path / "f"), {"000000": []})
    cfgp = str(tmp_path / "c.yaml")
    env = dict(os.environ, PYTHONPATH=ROOT)

    def run(cfg, *extra):
        with open(cfgp, "w") as f:
            yaml.safe_dump(cfg, f)
        out = str(tmp_path / "out")
        p = subprocess.run([sys.executable, "-m", "splatting", "dataset", "--config", cfgp, "--out", out, *extra],
                           capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
        return p.returncode, p.stderr.strip().splitlines(), os.path.exists(out)
    rc, err, made = run(seq_config(bikes, root, sequence={"ego": {"motion": "moving"}}))
    assert rc != 0 and len(err) == 1 and "sequence.ego.motion" in err[0] and not made
    rc, err, made = run(seq_config(bikes, root), "--frames", str(tmp_path / "nowhere"))
    assert rc != 0 and len(err) == 1 and "nowhere" in err[0] and not made


@pytest.mark.skipif(not os.path.isdir(DEV), reason="../shared/realism/kitti_dev absent")
def test_a_sequence_in_a_development_frame(bikes, tmp_path):
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    cfg = validate(seq_config(bikes, DEV, street={"cyclists": [1, 2], "parked_bikes": [0, 0], "distance_m": [6, 30],
                                                  "lateral_m": [-10, 10]}, count=1, seed=1))
    a = str(tmp_path / "a")
    generate(cfg, a, log=lambda m: None, progress=False)
    kt = os.path.join(a, "kitti_tracking", "training")
    assert read(os.path.join(kt, "calib", "0000.txt")) == read(os.path.join(DEV, "calib", "000000.txt"))
    own = [x for x in read(os.path.join(DEV, "label_2", "000000.txt")).decode().splitlines() if x.strip()]
    lines = read(os.path.join(kt, "label_02", "0000.txt")).decode().splitlines()
    for f in range(3):
        types = [x.split()[2] for x in lines if int(x.split()[0]) == f]
        assert types[len(types) - len(own):] == [o.split()[0] for o in own]
    with open(os.path.join(a, "annotations.json")) as f:
        doc = json.load(f)
    assert all(im["frame"]["frame"] == "000000" and im["frame"]["lidar"] for im in doc["images"])
    assert RIDER in {i["rider"] for im in doc["images"] for i in im["instances"]} or \
        all(im["dropped_placements"] >= 1 for im in doc["images"])


def test_motion_blur_in_a_frame_changes_only_the_cyclists_pixels(bikes, tmp_path):
    from splatting.dataset.frames.source import read_image
    from splatting.dataset.generate import Assets
    from splatting.dataset.sequences.render import make_frame
    root = ks.write_frames(str(tmp_path / "f"), {"000000": []})
    man = dict({m: 0.0 for m in ONLY}, straight=1.0)
    common = dict(length=3, manoeuvres=man, backgrounds={"shadow": False},
                  insert={"look": {"blur_sigma_px": 0.0, "noise_sigma": 0.0}},
                  street={"cyclists": [2, 2], "parked_bikes": [0, 0], "distance_m": [5, 12]})
    still = resolved(seq_config(bikes, root, **common))
    blur = resolved(seq_config(bikes, root, sequence={"exposure_s": 0.08, "blur_subframes": 3}, **common))
    rgb0, im0, anns0, _ = make_frame(still, 1, Assets(still))
    rgb1, im1, anns1, _ = make_frame(blur, 1, Assets(blur))
    assert anns0 == anns1 and len(im0["instances"]) == 2  # the labels of the mid-exposure instant
    diff = (rgb0 != rgb1).any(-1)
    frame = read_image(os.path.join(root, "image_2", "000000.png"))
    inside = np.zeros(diff.shape, bool)
    for a in anns0:
        x, y, w, h = (int(v) for v in a["bbox_amodal"])
        inside[max(y - 6, 0):y + h + 6, max(x - 12, 0):x + w + 12] = True  # the smear reaches past the instant's box
    assert diff.sum() > 50 and not (diff & ~inside).any()
    assert np.array_equal(rgb1[~inside], frame[~inside])  # the frame's own pixels stay its bytes


def test_only_the_frames_instant_ray_casts_the_scan(bikes, tmp_path):
    from splatting.dataset.generate import Assets, make_sample
    from splatting.dataset.sequences.blur import subframe_draw
    from splatting.dataset.sequences.draw import frame_draw
    from splatting.dataset.sequences.render import drawn
    root = ks.write_frames(str(tmp_path / "f"), {"000000": []}, with_velodyne=True)
    cfg = resolved(seq_config(bikes, root, sequence={"exposure_s": 0.05, "blur_subframes": 3}))
    assets = Assets(cfg)
    sd = drawn(cfg, 0, assets)
    assert sd["instances"]
    mid = make_sample(cfg, 1, assets, drawn=frame_draw(sd, 1), look_index=0)[3]["frame"]["scan"]
    sub = make_sample(cfg, 1, assets, drawn=subframe_draw(sd, 1, 0.1 + 0.0167), look_index=0)[3]["frame"]["scan"]
    assert mid is not None and len(mid) > 0 and sub is None

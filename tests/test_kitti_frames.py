"""Cyclists inserted into KITTI driving frames (issue 26): the KITTI object folder formats against
KITTI's documented layout, the road frame and camera from calib, placement, occlusion both ways,
labels and the resumable dataset command.  A small synthetic frame stands in for KITTI's data
(tests/kitti_synth.py); the tests reading ../shared/realism/kitti_dev skip when it is absent."""
import os

import numpy as np
import pytest

import kitti_synth as ks
from cyclist_formats.errors import UserError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEV = next((p for p in (os.path.join(ROOT, "..", "shared", "realism", "kitti_dev"),
                    os.path.join(ROOT, "..", "..", "shared", "realism", "kitti_dev")) if os.path.isdir(p)), "")
# label_2/000000.txt of KITTI's object training set (the devkit readme's fields)
PED = "Pedestrian 0.00 0 -0.20 712.40 143.00 810.73 307.92 1.89 0.48 1.20 1.84 1.47 8.41 0.01"


def write(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        f.write(text)
    return str(path)


# ---------------------------------------------------------------- formats

def test_calib_parses_kittis_layout_row_major(tmp_path):
    from cyclist_formats.kitti_frame import camera_of_P, parse_calib, velo_to_rect
    c = parse_calib(write(tmp_path / "c.txt", ks.calib_text()))
    assert set(c) == {"P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo"}
    assert c["P2"].shape == (3, 4) and c["P2"][0, 3] == pytest.approx(200.0 * 0.06) and c["P2"][1, 2] == 60.0
    assert c["P1"][0, 3] == pytest.approx(-200.0 * 0.54)
    assert c["Tr_velo_to_cam"][1, 3] == -0.08 and c["Tr_velo_to_cam"][0, 1] == -1.0  # row-major 3x4
    assert c["Tr_imu_to_velo"][0, 3] == -0.81
    # a Velodyne point 10 m ahead, 2 m left, 1 m up: rect x = -2, y = -1 - 0.08, z = 10 - 0.27
    T = velo_to_rect(c)
    assert np.allclose(T @ [10.0, 2.0, 1.0, 1.0], [-2.0, -1.08, 9.73, 1.0])
    # camera 2 stands 6 cm to the left of camera 0 (t = K^-1 P2[:, 3])
    K, t = camera_of_P(c["P2"])
    assert np.allclose(t, [0.06, 0.0, 0.0]) and K[0, 0] == 200.0


def test_calib_of_the_tracking_layout_and_refusals(tmp_path):
    from cyclist_formats.kitti_frame import parse_calib
    txt = ks.calib_text().replace("R0_rect:", "R_rect:").replace("Tr_velo_to_cam:", "Tr_velo_cam:")
    assert parse_calib(write(tmp_path / "t.txt", txt))["R0_rect"].shape == (3, 3)
    lines = ks.calib_text().splitlines()
    bad = {"missing": "\n".join(x for x in lines if not x.startswith("P2")),
           "nan": ks.calib_text().replace("P2: 2.000000000000e+02", "P2: nan"),
           "short": ks.calib_text().replace("R0_rect: 1.000000000000e+00 ", "R0_rect: "),
           "word": ks.calib_text().replace("P3: 2.000000000000e+02", "P3: abc")}
    want = {"missing": "lacks P2", "nan": ":3: values must be finite", "short": ":5: R0_rect has 9 values, got 8",
            "word": ":4: 'abc' is not a number"}
    for k, t in bad.items():
        with pytest.raises(UserError, match=want[k]):
            parse_calib(write(tmp_path / f"{k}.txt", t))


def test_label_rows_known_answer_round_trip_and_refusals(tmp_path):
    from cyclist_formats.kitti_frame import FIELDS, label_line, parse_label_line, parse_labels, with_occluded
    o = parse_label_line(PED)
    assert list(o) == list(FIELDS)
    assert (o["type"], o["truncated"], o["occluded"], o["alpha"]) == ("Pedestrian", 0.0, 0, -0.2)
    assert (o["x1"], o["y1"], o["x2"], o["y2"]) == (712.40, 143.00, 810.73, 307.92)
    assert (o["h"], o["w"], o["l"], o["x"], o["y"], o["z"], o["rotation_y"]) == (1.89, 0.48, 1.20, 1.84, 1.47, 8.41, 0.01)
    assert label_line(o) == PED + "\n"
    assert parse_label_line(PED + " 0.93")["score"] == 0.93  # 16 columns: a detector's score
    assert with_occluded(PED, 2) == PED.replace(" 0 -0.20", " 2 -0.20")
    rows = parse_labels(write(tmp_path / "l.txt", PED + "\n\nDontCare -1 -1 -10 5.00 229.89 214.12 367.61 -1 -1 -1 "
                                                      "-1000 -1000 -1000 -10\n"))
    assert [r[0]["type"] for r in rows] == ["Pedestrian", "DontCare"] and rows[0][1] == PED
    fourteen = " ".join(PED.split()[:14])
    with pytest.raises(UserError, match=r"l14.txt:2: KITTI label lines have 15 fields .* got 14"):
        parse_labels(write(tmp_path / "l14.txt", PED + "\n" + fourteen + "\n"))
    with pytest.raises(UserError, match=r"lnan.txt:1: values must be finite"):
        parse_labels(write(tmp_path / "lnan.txt", PED.replace("8.41", "nan") + "\n"))
    with pytest.raises(UserError, match=r"occluded is one of"):
        parse_label_line(PED.replace(" 0 -0.20", " 7 -0.20"))


def test_plane_parses_avods_layout_and_refuses_nan(tmp_path):
    from cyclist_formats.kitti_frame import parse_plane
    # planes/000000.txt of KITTI's object set as AVOD ships it
    txt = "# Matrix\nWIDTH 4\nHEIGHT 1\n-7.051729e-03 -9.997791e-01 -1.980151e-02 1.680367e+00 \n"
    a, b, c, d = parse_plane(write(tmp_path / "p.txt", txt))
    n = np.linalg.norm([-7.051729e-03, -9.997791e-01, -1.980151e-02])
    assert (a, b, c, d) == pytest.approx((-7.051729e-03 / n, -9.997791e-01 / n, -1.980151e-02 / n, 1.680367 / n))
    # the same plane written with the normal pointing down is turned up (b < 0)
    flipped = parse_plane(write(tmp_path / "f.txt", "# Plane\nWidth 4\nHeight 1\n0 1 0 -1.65\n"))
    assert flipped == pytest.approx((0.0, -1.0, 0.0, 1.65))
    with pytest.raises(UserError, match=r"nan.txt:4: values must be finite"):
        parse_plane(write(tmp_path / "nan.txt", txt.replace("1.680367e+00", "nan")))
    with pytest.raises(UserError, match=r"w.txt:2: a plane file is WIDTH 4"):
        parse_plane(write(tmp_path / "w.txt", txt.replace("WIDTH 4", "WIDTH 3")))
    with pytest.raises(UserError, match=r"not near the vertical"):
        parse_plane(write(tmp_path / "v.txt", "1 0 0 2\n"))


def test_velodyne_reads_float32_quadruples_and_refuses_odd_sizes(tmp_path):
    from cyclist_formats.kitti_frame import read_velodyne
    pts = np.array([[1.5, -2.0, 0.25, 0.5], [10.0, 0.0, -1.7, 0.0]], np.float32)
    p = tmp_path / "v.bin"
    pts.tofile(p)
    assert os.path.getsize(p) == 32
    assert np.array_equal(read_velodyne(str(p)), pts)
    with open(p, "ab") as f:
        f.write(b"\0" * 4)
    with pytest.raises(UserError, match="36 bytes is not a whole number of points"):
        read_velodyne(str(p))
    np.array([[1.0, np.nan, 0.0, 0.0]], np.float32).tofile(p)
    with pytest.raises(UserError, match="point 0 is not finite"):
        read_velodyne(str(p))


def test_folder_check_names_the_first_bad_file(tmp_path):
    from cyclist_formats.kitti_frame import check_folder
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [PED], "000001": [PED]}, with_velodyne=True)
    frames = check_folder(root)
    assert list(frames) == ["000000", "000001"] and frames["000001"]["plane"] == pytest.approx((0, -1, 0, 1.65))
    os.remove(os.path.join(root, "calib", "000001.txt"))
    with pytest.raises(UserError, match=r"calib/000001.txt: no such file \(frame 000001 needs its calib\)"):
        check_folder(root)
    with pytest.raises(UserError, match="no such frames folder"):
        check_folder(str(tmp_path / "nowhere"))


@pytest.mark.skipif(not os.path.isdir(DEV), reason="../shared/realism/kitti_dev absent")
def test_the_development_frames_parse():
    from cyclist_formats.kitti_frame import check_folder, read_velodyne
    frames = check_folder(DEV)
    assert len(frames) == 10
    f = frames["000000"]
    assert f["labels"][0][1] == PED and f["plane"][3] == pytest.approx(1.68, abs=0.01)
    assert read_velodyne(f["velodyne"]).shape[1] == 4


# ---------------------------------------------------------------- samples on a synthetic frame

from helpers import CITY_KEYPOINTS, RIDER, resolved, small_config, with_blocks  # noqa: E402


def frames_config(bikes, frames, **kw):
    cfg = small_config(bikes, mode="frames", frames=frames, count=4,
                       street={"cyclists": [2, 3], "parked_bikes": [0, 1], "distance_m": [5, 30], "lateral_m": [-8, 8]},
                       pose={"theta_s_deg": [-12, 12], "theta_x_deg": [-6, 6]})
    cfg.pop("image_size")
    return with_blocks(cfg, **kw)


def fixed(monkeypatch, instances):
    """Every sample index i: frame i mod n with these instances [(rider, theta_y, X, Z)] (world)."""
    from splatting.dataset import generate
    from splatting.dataset.frames import source

    def draw(cfg, index):
        fid = source.frame_id(cfg, index)
        inst = [{"kind": "cyclist" if r else "parked", "bike": "city_t", "rider": r,
                 "pose": [30.0, 0.0, 0.0, yaw, 0.0, x, 0.0, z]} for r, yaw, x, z in instances]
        return {"instances": inst, "dropped": 0, "camera": {"preset": "frame", "frame": fid},
                "background": {"kind": "frame", "frame": fid}}
    monkeypatch.setattr(generate, "draw", draw)


def rim_lowest(kp, pose):
    """Lowest world points of both posed tyres by the tests' own rotation maths (helpers)."""
    from helpers import ref_global, rotate_about
    axis = [a - b for a, b in zip(kp["steer_top"], kp["steer_bottom"])]
    out = []
    for name in ("front_axle", "rear_axle"):
        a = kp[name]
        r = a[1] - kp["ground"][1]
        pts = []
        for k in range(360):
            p = [a[0] + r * np.cos(np.radians(k)), a[1] + r * np.sin(np.radians(k)), a[2]]
            if name == "front_axle":
                p = rotate_about(p, kp["steer_bottom"], axis, np.radians(pose[1]))
            pts.append(ref_global(p, pose))
        out.append(min(pts, key=lambda q: q[1]))
    return out


def test_tyres_touch_a_tilted_road_plane_and_never_stand_in_a_labelled_box(bikes, tmp_path):
    from splatting.dataset.frames.road import Road
    from splatting.dataset.generate import Assets, make_sample
    cars = [ks.box_row("Car", 1.5, 1.7, 4.2, x, 1.65, z, ry) for x, z, ry in
            ((-3.0, 12.0, 1.57), (2.5, 9.0, 1.5), (0.0, 20.0, -1.6), (-1.5, 28.0, 1.6), (3.5, 16.0, 0.1))]
    root = ks.write_frames(str(tmp_path / "f"), {"000000": cars})
    # a road tilted by ~2.3 deg about x and 1.7 deg about z: a x + b y + c z + d = 0, normal up
    n = np.array([0.03, -1.0, 0.04])
    n /= np.linalg.norm(n)
    with open(os.path.join(root, "planes", "000000.txt"), "w") as f:
        f.write("# Plane\nWidth 4\nHeight 1\n" + " ".join(f"{x:.9f}" for x in (*n, 1.65)) + "\n")
    cfg = resolved(frames_config(bikes, root, count=6, street={"cyclists": [3, 3], "parked_bikes": [1, 1]},
                                 insert={"box_margin_m": 0.5}))
    assets = Assets(cfg)
    road = Road((*n, 1.65), ks.P2(), ks.W, ks.H)
    placed = 0
    for i in range(6):
        _, image, _, extras = make_sample(cfg, i, assets)
        for rec in image["instances"]:
            for p in rim_lowest(CITY_KEYPOINTS, rec["pose"]):
                rect = road.to_rect(np.array([p]))[0]
                assert abs(rect @ n + 1.65) < 0.03  # height above the file's plane, by its own equation
            placed += 1
        for o in extras["kitti"]:  # the inserted box's centre is outside every car's footprint + margin
            for c in cars:
                v = [float(x) for x in c.split()[8:15]]
                h, w, l, x, y, z, ry = v
                dx, dz = o["x"] - x, o["z"] - z
                lx, lz = dx * np.cos(ry) - dz * np.sin(ry), dx * np.sin(ry) + dz * np.cos(ry)
                assert abs(lx) > l / 2 + 0.5 or abs(lz) > w / 2 + 0.5, (o, c)
    assert placed >= 12


def test_a_labelled_car_in_front_hides_the_cyclist_and_it_raises_a_pedestrian_behind(bikes, tmp_path, monkeypatch):
    from pycocotools import mask as mu
    from cyclist_formats.kitti_frame import parse_label_line
    from splatting.dataset.generate import Assets, make_sample
    from splatting.dataset.labels import CATEGORY_IDS
    car = ks.box_row("Car", 1.5, 1.8, 4.0, 0.0, 1.65, 5.0, 0.0)
    ped = ks.box_row("Pedestrian", 1.75, 0.6, 0.8, 0.3, 1.65, 14.0, 1.57)
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [car], "000001": [ped], "000002": []})
    fixed(monkeypatch, [(RIDER, -90.0, 0.0, 8.0)])  # riding away from the camera, 8 m ahead
    cfg = resolved(frames_config(bikes, root, insert={"look": {"match": False}}, backgrounds={"shadow": False}))
    assets = Assets(cfg)
    res = {i: make_sample(cfg, i, assets) for i in range(3)}

    def ann(i, key):
        return next(a for a in res[i][2] if a["category_id"] == CATEGORY_IDS[key])
    free, hidden = ann(2, "cyclist"), ann(0, "cyclist")
    assert free["visibility"] > 0.95 and free["occlusion"] == 0
    assert hidden["visibility"] < 0.6 and hidden["occlusion"] >= 1
    assert hidden["area"] < 0.6 * free["area"]
    # the bike is wholly behind the bonnet: no visible pixel, no annotation of its own
    assert not any(a["category_id"] == CATEGORY_IDS["bicycle"] for a in res[0][2])
    kr_free, kr_hid = (np.array(ann(i, "rider")["keypoints"]).reshape(-1, 3) for i in (2, 0))
    assert (kr_hid[:5, 2] == kr_free[:5, 2]).all()  # the head's points as seen without the car
    # the head shows above the car: the hidden rider's visible mask reaches the top of its amodal box
    # (its face and ears, seen from behind under a helmet, are no visible keypoints either way)
    rider_hid = ann(0, "rider")
    m = mu.decode(rider_hid["segmentation"]).astype(bool)
    x, y, w, h = rider_hid["bbox_amodal"]
    band = m[int(y):int(y + 0.15 * h) + 1, int(x):int(x + w) + 1]
    assert band.mean() > 0.1, band.mean()  # the head fills about a third of the box's top band
    assert (kr_free[15:, 2] == 2).any() and (kr_hid[15:, 2] == 1).all()  # the ankles do not
    kit = res[0][3]["kitti"][0]
    assert kit["occluded"] >= 1
    # the car's own row is kept; the pedestrian behind the cyclist is now occluded, every other byte kept
    assert res[0][3]["frame"]["frame_lines"] == [car]
    lines = res[1][3]["frame"]["frame_lines"]
    new = parse_label_line(lines[0])
    assert new["occluded"] >= 1 and lines[0].split()[:2] + lines[0].split()[3:] == ped.split()[:2] + ped.split()[3:]
    assert res[1][1]["frame"]["occlusion_raised"][0][2] > 0.1


def test_the_image_changes_only_where_the_cyclists_are(bikes, tmp_path, monkeypatch):
    from pycocotools import mask as mu
    from splatting.dataset.frames.source import read_image
    from splatting.dataset.generate import Assets, make_sample
    root = ks.write_frames(str(tmp_path / "f"), {"000000": []})
    fixed(monkeypatch, [(RIDER, -90.0, 0.0, 8.0), (RIDER, 0.0, 2.5, 14.0)])
    cfg = resolved(frames_config(bikes, root, backgrounds={"shadow": False},
                                 insert={"look": {"blur_sigma_px": 0.0, "noise_sigma": 0.01}}))
    rgb, image, anns, _ = make_sample(cfg, 0, Assets(cfg))
    frame = read_image(os.path.join(root, "image_2", "000000.png"))
    diff = (rgb != frame).any(-1)
    inside = np.zeros(diff.shape, bool)
    for a in anns:
        inside |= mu.decode(a["segmentation_amodal"]).astype(bool)
    # grown by 3 px: the Gaussians' faint tails below the mask threshold (alpha 0.5) still tint the frame
    grown = inside.copy()
    for dy in range(-3, 4):
        for dx in range(-3, 4):
            grown |= np.roll(np.roll(inside, dy, 0), dx, 1)
    assert diff.sum() > 100 and not (diff & ~grown).any()
    assert image["background"]["look"]["noise_sigma"] == 0.01


def test_never_placed_in_an_unlabelled_walls_lidar_shadow(bikes, tmp_path):
    from splatting.dataset.generate import draw
    root = ks.write_frames(str(tmp_path / "f"), {"000000": []}, with_velodyne=True)
    scan, end = ks.scan_with_wall(12.0, 1.0)
    scan.tofile(os.path.join(root, "velodyne", "000000.bin"))
    assert 28 < end < 30
    zs = {}
    for use in (True, False):
        cfg = resolved(frames_config(bikes, root, street={"cyclists": [3, 3], "parked_bikes": [0, 0],
                                                          "distance_m": [5, 40], "lateral_m": [-6, 6]},
                                     insert={"lidar": use}))
        zs[use] = [float(i["pose"][7]) for k in range(10) for i in draw(cfg, k)["instances"]]
    # world Z is rect z here (level road below camera 0)
    assert len(zs[True]) >= 20 and not any(12.0 - 1.0 < z < end - 0.5 for z in zs[True]), zs[True]
    assert sum(z < 11 for z in zs[True]) >= 20  # (beyond `end` the sensor's beams graze the wall: kept clear too)
    # without the scan nothing knows the wall is there: the same draws land behind it
    assert sum(12.5 < z < end - 0.5 for z in zs[False]) >= 5


def test_dataset_command_kitti_layout_resume_and_shards_byte_identical(bikes, tmp_path):
    from cyclist_formats.kitti_frame import parse_labels, read_velodyne
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    car = ks.box_row("Car", 1.5, 1.7, 4.2, -3.0, 1.65, 12.0, 1.57)
    ped = ks.box_row("Pedestrian", 1.75, 0.6, 0.8, 2.0, 1.65, 15.0, 1.57, occluded=1)
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [car, ped], "000001": [car]}, with_velodyne=True)
    cfg = validate(frames_config(bikes, root, count=3, labels={"formats": ["coco", "kitti"]},
                                 street={"cyclists": [1, 2], "parked_bikes": [0, 1], "distance_m": [5, 25]}))
    a, b = str(tmp_path / "a"), str(tmp_path / "b")
    generate(cfg, a, log=lambda m: None, progress=False)
    generate(cfg, b, log=lambda m: None, progress=False)
    os.remove(os.path.join(b, "shards", "000001.json"))
    os.remove(os.path.join(b, "kitti", "training", "velodyne", "000002.bin"))
    os.remove(os.path.join(b, "kitti", "training", "label_2", "000002.txt"))
    os.remove(os.path.join(b, "annotations.json"))
    r = generate(cfg, b, log=lambda m: None, progress=False)
    assert r["generated"] == 2
    kt = os.path.join("kitti", "training")
    for rel in ("annotations.json", "images/000001.png", f"{kt}/label_2/000002.txt", f"{kt}/velodyne/000002.bin",
                f"{kt}/velodyne/000001.bin", f"{kt}/image_2/000001.png", "kitti/ImageSets/train.txt"):
        with open(os.path.join(a, rel), "rb") as fa, open(os.path.join(b, rel), "rb") as fb:
            assert fa.read() == fb.read(), rel
    # shards (a Slurm array's tasks) then a merge: the same bytes
    from splatting.dataset.merge import merge_dataset
    c = str(tmp_path / "c")
    for k in (0, 1):
        generate(cfg, c, log=lambda m: None, progress=False, shard=(k, 2))
    merge_dataset(c)
    for rel in ("annotations.json", "images/000002.png", f"{kt}/velodyne/000001.bin", f"{kt}/label_2/000000.txt"):
        with open(os.path.join(a, rel), "rb") as fa, open(os.path.join(c, rel), "rb") as fc:
            assert fa.read() == fc.read(), rel
    # KITTI layout: calib and planes copied byte for byte, the frame's rows first, then the inserted ones
    for i, fid in ((0, "000000"), (1, "000001"), (2, "000000")):
        for sub in ("calib", "planes"):
            with open(os.path.join(a, kt, sub, f"{i:06d}.txt"), "rb") as f, open(os.path.join(root, sub, fid + ".txt"), "rb") as g:
                assert f.read() == g.read()
        rows = [r for r, _ in parse_labels(os.path.join(a, kt, "label_2", f"{i:06d}.txt"))]
        own = 2 if fid == "000000" else 1
        assert rows[0]["type"] == "Car" and all(r["type"] in ("Cyclist", "Misc") for r in rows[own:]) and len(rows) > own
        if own == 2:
            assert rows[1]["occluded"] >= 1  # kept or raised, never lowered
        scan = read_velodyne(os.path.join(a, kt, "velodyne", f"{i:06d}.bin"))
        src = read_velodyne(os.path.join(root, "velodyne", fid + ".bin"))
        assert scan.shape[1] == 4 and not np.array_equal(scan, src)
    import json
    with open(os.path.join(a, "annotations.json")) as f:
        doc = json.load(f)
    assert [im["frame"]["frame"] for im in doc["images"]] == ["000000", "000001", "000000"]
    assert all("lidar_points" in an for an in doc["annotations"])
    assert sum(an["lidar_points"] for an in doc["annotations"]) > 0


def test_command_refuses_bad_frames_in_one_line(bikes, tmp_path):
    import subprocess
    import sys
    import yaml
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [PED]})
    cfgp = str(tmp_path / "c.yaml")
    with open(cfgp, "w") as f:
        yaml.safe_dump(frames_config(bikes, root), f)
    env = dict(os.environ, PYTHONPATH=ROOT)

    def run(*extra):
        out = str(tmp_path / "out")
        p = subprocess.run([sys.executable, "-m", "splatting", "dataset", "--config", cfgp, "--out", out, *extra],
                           capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
        return p.returncode, p.stderr.strip().splitlines(), os.path.exists(out)
    rc, err, made = run("--frames", str(tmp_path / "nowhere"))
    assert rc != 0 and len(err) == 1 and "nowhere" in err[0] and not made
    with open(os.path.join(root, "label_2", "000000.txt"), "w") as f:
        f.write(" ".join(PED.split()[:14]) + "\n")
    rc, err, made = run()
    assert rc != 0 and len(err) == 1 and "label_2/000000.txt:1" in err[0] and "got 14" in err[0] and not made
    with open(os.path.join(root, "label_2", "000000.txt"), "w") as f:
        f.write(PED + "\n")
    with open(os.path.join(root, "velodyne_bad.bin"), "wb") as f:
        f.write(b"\0" * 20)
    os.makedirs(os.path.join(root, "velodyne"))
    os.replace(os.path.join(root, "velodyne_bad.bin"), os.path.join(root, "velodyne", "000000.bin"))
    rc, err, made = run()
    assert rc != 0 and len(err) == 1 and "20 bytes is not a whole number of points" in err[0] and not made


def test_behind_a_labelled_car_only_when_labelled_occluded(bikes, tmp_path):
    """Spots in a labelled car's LiDAR shadow are allowed (insert.behind_cars_share) and then the
    inserted cyclist's row says occluded; the road in the shadow has no scan points."""
    from splatting.dataset.generate import Assets, make_sample
    car = ks.box_row("Car", 1.5, 1.8, 4.2, 0.0, 1.65, 10.0, 0.0)  # crossing: x -2.1..2.1, z 9.1..10.9
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [car]}, with_velodyne=True)
    scan = ks.scan([(1.5, 1.8, 4.2, 0.0, 1.65, 10.0, 0.0)])
    T = np.eye(4)
    T[:3] = ks.TR_VELO
    rect = (T @ np.column_stack([scan[:, :3], np.ones(len(scan))]).T).T[:, :3]
    road = np.abs(rect[:, 1] - ks.CAM_H) < 0.01
    shadow = road & (rect[:, 2] > 9.1) & (np.abs(rect[:, 0]) / (rect[:, 2] + 0.27) < 2.1 / 9.37)
    scan[~shadow].tofile(os.path.join(root, "velodyne", "000000.bin"))
    cfg = resolved(frames_config(bikes, root, count=4, labels={"formats": ["coco", "kitti"]},
                                 street={"cyclists": [2, 2], "parked_bikes": [0, 0], "distance_m": [5, 30]},
                                 insert={"behind_cars_share": 1.0}))
    assets = Assets(cfg)
    in_shadow = 0
    for i in range(4):
        _, image, _, extras = make_sample(cfg, i, assets)
        for rec, row in zip(image["instances"], extras["kitti"]):
            x, z = -rec["pose"][5], rec["pose"][7]  # world X is rect -x on this level road
            if z > 10.9 and abs(x) / (z + 0.27) < 2.1 / 9.37:
                in_shadow += 1
                assert row["occluded"] >= 1, (rec["pose"], row)
    assert in_shadow >= 3


def test_a_frame_with_no_room_keeps_its_bytes(bikes, tmp_path):
    from splatting.dataset.frames.source import read_image
    from splatting.dataset.generate import Assets, make_sample
    wall = ks.box_row("Truck", 3.0, 2.0, 40.0, 0.0, 1.65, 8.5, 0.0)  # 40 m across the road at 7.5-9.5 m
    root = ks.write_frames(str(tmp_path / "f"), {"000000": [wall]})
    cfg = resolved(frames_config(bikes, root, street={"cyclists": [1, 1], "parked_bikes": [0, 0], "distance_m": [8, 9],
                                                      "max_tries": 20}, lod={"enabled": True}))
    rgb, image, anns, extras = make_sample(cfg, 0, Assets(cfg))
    assert image["instances"] == [] and image["dropped_placements"] == 1 and anns == []
    assert np.array_equal(rgb, read_image(os.path.join(root, "image_2", "000000.png")))
    assert extras["frame"]["frame_lines"] == [wall] and extras["kitti"] == []

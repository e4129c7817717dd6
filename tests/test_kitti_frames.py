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

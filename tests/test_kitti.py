"""KITTI object format (issue 13): field list against KITTI's documented example, calib layout,
3D boxes that project onto the 2D boxes, rotation_y and alpha by KITTI's definitions."""
import math
import os

import numpy as np
import pytest

from helpers import RIDER, fixed_scene, small_config, street_config, write_test_bike

# training/label_2/000000.txt of the KITTI object benchmark (devkit readme fields, 15 per line)
KITTI_LINE = "Pedestrian 0.00 0 -0.20 712.40 143.00 810.73 307.92 1.89 0.48 1.20 1.84 1.47 8.41 0.01\n"


def test_label_line_known_answer_and_round_trip():
    from splatting.dataset.kitti import FIELDS, label_line, parse_label_line
    o = parse_label_line(KITTI_LINE)
    assert list(o) == list(FIELDS)
    assert o["type"] == "Pedestrian" and o["occluded"] == 0 and o["alpha"] == -0.20
    assert (o["x1"], o["y1"], o["x2"], o["y2"]) == (712.40, 143.00, 810.73, 307.92)
    assert (o["h"], o["w"], o["l"]) == (1.89, 0.48, 1.20) and (o["x"], o["y"], o["z"]) == (1.84, 1.47, 8.41)
    assert o["rotation_y"] == 0.01
    assert label_line(o) == KITTI_LINE
    with pytest.raises(ValueError):
        parse_label_line("Car 0 0")


@pytest.fixture(scope="module")
def side_on(tmp_path_factory):
    """A full-resolution KITTI frame with a cyclist riding along camera +x, 9 m ahead."""
    import torch
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("kitti")
    write_test_bike(str(root))
    mp = pytest.MonkeyPatch()
    fixed_scene(mp, [(RIDER, 180.0, 0.5, 9.0), (RIDER, -90.0, -3.0, 14.0)])
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    cfg = validate(street_config(str(root), count=1, camera={"preset": "kitti", "scale": 1.0},
                                 labels={"formats": ["coco", "kitti"]}))
    out = str(root / "out")
    generate(cfg, out, log=lambda m: None, progress=False)
    mp.undo()
    return out


def read_calib(path):
    out = {}
    with open(path) as f:
        for line in f:
            k, v = line.split(":", 1)
            out[k] = np.array([float(x) for x in v.split()])
    return out


def test_calib_file_has_kittis_matrices(side_on):
    c = read_calib(os.path.join(side_on, "kitti", "training", "calib", "000000.txt"))
    assert list(c) == ["P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo"]
    assert [len(v) for v in c.values()] == [12, 12, 12, 12, 9, 12, 12]
    P2 = c["P2"].reshape(3, 4)
    assert np.allclose(P2[:, :3], [[721.5377, 0, 609.5593], [0, 721.5377, 172.854], [0, 0, 1]])  # level camera
    assert np.allclose(c["R0_rect"], np.eye(3).ravel())
    with open(os.path.join(side_on, "kitti", "ImageSets", "train.txt")) as f:
        assert f.read() == "000000\n"


def _side_on_labels(side_on):
    from splatting.dataset.kitti import parse_label_line
    c = read_calib(os.path.join(side_on, "kitti", "training", "calib", "000000.txt"))
    with open(os.path.join(side_on, "kitti", "training", "label_2", "000000.txt")) as f:
        return [parse_label_line(line) for line in f], c["P2"].reshape(3, 4)


def test_3d_boxes_project_onto_the_2d_boxes_and_angles_follow_kitti(side_on):
    check_side_on_labels(*_side_on_labels(side_on))


@pytest.mark.parametrize("wrong", [
    ("3D box 1 m off along x", lambda o: dict(o, x=o["x"] + 1.0)),
    ("heading turned 90 deg (alpha with it)", lambda o: dict(o, rotation_y=o["rotation_y"] + math.pi / 2,
                                                             alpha=o["alpha"] + math.pi / 2)),
    ("width and length swapped", lambda o: dict(o, w=o["l"], l=o["w"])),
    ("box 0.5 m under the road", lambda o: dict(o, y=o["y"] + 0.5)),
    ("alpha of another convention", lambda o: dict(o, alpha=o["rotation_y"])),
    ("2D box shifted 20 px", lambda o: dict(o, x1=o["x1"] + 20, x2=o["x2"] + 20)),
], ids=lambda w: w[0])
def test_a_wrong_kitti_label_fails_the_check(side_on, wrong):
    """The label check above is not vacuous: the writer's real labels, each broken one way in memory
    (the side-on cyclist's line), fail it."""
    objs, P2 = _side_on_labels(side_on)
    with pytest.raises(AssertionError):
        check_side_on_labels([wrong[1](objs[0])] + objs[1:], P2)


def check_side_on_labels(objs, P2):
    from splatting.dataset.kitti import corners, project_rect
    assert [o["type"] for o in objs] == ["Cyclist", "Cyclist"]
    for i, o in enumerate(objs):
        uv = project_rect(P2, corners(o["h"], o["w"], o["l"], [o["x"], o["y"], o["z"]], o["rotation_y"]))
        box = (uv[0].min(), uv[1].min(), uv[0].max(), uv[1].max())
        # contains the amodal 2D box (label values are rounded to 0.01; pixel edges; the 3D box widens
        # each Gaussian to where it alone reaches alpha 0.5, and a dense stack of them (the mesh
        # avatar's helmet shell) reaches 0.5 about 1 cm further, ~1 px at 9 m)
        assert box[0] <= o["x1"] + 1.0 and box[1] <= o["y1"] + 1.0
        assert box[2] >= o["x2"] - 1.0 and box[3] >= o["y2"] - 1.0
        assert o["alpha"] == pytest.approx(math.remainder(o["rotation_y"] - math.atan2(o["x"], o["z"]), 2 * math.pi),
                                           abs=0.011)
        if i == 0:  # side-on: the box matches within a few pixels on every side
            assert np.abs(np.array(box) - [o["x1"], o["y1"], o["x2"], o["y2"]]).max() < 6
    assert objs[0]["rotation_y"] == pytest.approx(0.0, abs=0.006)  # riding along camera +x
    assert objs[1]["rotation_y"] == pytest.approx(-math.pi / 2, abs=0.006)  # riding away from the camera
    # bottom centre on the road, 1.65 m under the camera; heights of a cyclist
    for o in objs:
        assert o["y"] == pytest.approx(1.65, abs=0.1) and 1.5 < o["h"] < 2.1 and 1.5 < o["l"] < 2.2


def test_ring_presets_write_valid_kitti_files(tmp_path):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from splatting.dataset.kitti import parse_label_line
    write_test_bike(str(tmp_path))
    cfg = validate(small_config(str(tmp_path), count=1, labels={"formats": ["kitti"]}))
    generate(cfg, str(tmp_path / "o"), log=lambda m: None, progress=False)
    with open(tmp_path / "o" / "kitti" / "training" / "label_2" / "000000.txt") as f:
        objs = [parse_label_line(line) for line in f]
    assert len(objs) == 1 and objs[0]["type"] == "Cyclist" and objs[0]["z"] > 5
    assert os.path.isfile(tmp_path / "o" / "kitti" / "training" / "image_2" / "000000.png")


def test_the_kitti_image_is_a_hard_link_to_the_coco_image(tmp_path):
    # docs/labels.md: image_2 is a hard link to images/ where the file system allows (tmp_path does)
    from splatting.dataset.kitti import link_or_copy
    src = tmp_path / "images" / "000000.png"
    src.parent.mkdir()
    src.write_bytes(b"\x89PNG not decoded here")
    dst = tmp_path / "kitti" / "training" / "image_2" / "000000.png"
    link_or_copy(str(src), str(dst))
    assert os.path.samefile(src, dst)
    assert not [n for n in os.listdir(dst.parent) if n != dst.name]  # no temporary left beside it

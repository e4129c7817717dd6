"""cyclist_formats: the numpy-only owners of the file contract, checked against independent
readers (plyfile) and hand-written expectations."""
import json
import math

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from cyclist_formats import bike_folder, ply, pose, ring
from cyclist_formats.errors import UserError


def _plyfile_write(path, arr, faces=None, text=False, byte_order="<"):
    els = [PlyElement.describe(arr, "vertex")]
    if faces is not None:
        f = np.zeros(len(faces), dtype=[("vertex_indices", "i4", (3,))])
        f["vertex_indices"] = faces
        els.append(PlyElement.describe(f, "face"))
    PlyData(els, text=text, byte_order=byte_order).write(str(path))


@pytest.mark.parametrize("text,order", [(False, "<"), (False, ">"), (True, "=")])
def test_ply_reads_what_plyfile_writes(tmp_path, text, order):
    rng = np.random.default_rng(0)
    arr = np.zeros(7, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for k in "xyz":
        arr[k] = rng.normal(size=7)
    for k in ("red", "green", "blue"):
        arr[k] = rng.integers(0, 256, 7)
    faces = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 6]])
    p = tmp_path / "m.ply"
    _plyfile_write(p, arr, faces, text, order)
    v, f, c = ply.read_colored_mesh(p)
    assert np.allclose(v, np.stack([arr["x"], arr["y"], arr["z"]], 1), atol=1e-6)
    assert (f == faces).all()
    assert np.allclose(c * 255, np.stack([arr["red"], arr["green"], arr["blue"]], 1))


def test_written_ply_reads_back_in_plyfile(tmp_path):
    pts = np.arange(12, dtype=np.float32).reshape(4, 3)
    ply.write_points(tmp_path / "p.ply", pts, normals=pts * 0 + 1, rgb=np.full((4, 3), 200))
    v = PlyData.read(str(tmp_path / "p.ply"))["vertex"].data
    assert np.allclose(np.stack([v["x"], v["y"], v["z"]], 1), pts) and (v["red"] == 200).all()
    xyz, col = ply.read_points(tmp_path / "p.ply")
    assert np.allclose(xyz, pts) and np.allclose(col, 200 / 255)


def test_gaussian_ply_needs_binary_little_endian_and_fields(tmp_path):
    arr = np.zeros(2, dtype=[(k, "f4") for k in ply.GAUSSIAN_FIELDS])
    _plyfile_write(tmp_path / "be.ply", arr, byte_order=">")
    with pytest.raises(UserError, match="binary_little_endian"):
        ply.read_gaussians(tmp_path / "be.ply")
    _plyfile_write(tmp_path / "few.ply", np.zeros(2, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")]))
    with pytest.raises(UserError, match="missing fields"):
        ply.read_gaussians(tmp_path / "few.ply")
    raw = (tmp_path / "few.ply").read_bytes()
    (tmp_path / "cut.ply").write_bytes(raw[:-5])
    with pytest.raises(UserError, match="truncated"):
        ply.read_ply(tmp_path / "cut.ply")
    with pytest.raises(UserError, match="no such"):
        ply.read_gaussians(tmp_path / "none.ply")


def test_pose_parsing_names_the_field():
    assert pose.parse_pose_string("1,2,3,4,5,6,7,8").tolist() == [1, 2, 3, 4, 5, 6, 7, 8]
    with pytest.raises(UserError, match="theta_x_deg"):
        pose.parse_pose_string("1,2,x,4,5,6,7,8")
    with pytest.raises(UserError, match="t_y_m"):
        pose.check_poses([0, 0, 0, 0, 0, 0, math.nan, 0])
    with pytest.raises(UserError, match="8 comma-separated"):
        pose.parse_pose_string("1,2")
    d = pose.pose_dict([1, 2, 3, 4, 5, 6, 7, 8])
    assert list(d) == list(pose.POSE_FIELDS) and pose.poses_from_json([d]).tolist() == [[1, 2, 3, 4, 5, 6, 7, 8]]


def test_ring_view0_and_orbit_view_agree():
    R, T, c = ring.view(0, (0, 0.5, 0))
    assert np.allclose(R, np.diag([-1, -1, 1])) and np.allclose(c, [0, 0.5, -12])
    for az in (0.0, 40.0, 230.0):
        R1, T1, _ = ring.azimuth_view(az, (0, 0.5, 0))
        R2, T2, _ = ring.orbit_view(az, 0.0, 12.0, (0, 0.5, 0))
        assert np.allclose(R1, R2, atol=1e-12) and np.allclose(T1, T2, atol=1e-9)


def test_cameras_json_errors(tmp_path):
    p = tmp_path / "cameras.json"
    p.write_text(json.dumps(ring.ring([0, 0.5, 0], n=3)))
    cams, orbit = ring.read_cameras_json(p)
    assert list(cams) == ["camera0000", "camera0001", "camera0002"] and orbit == [0, 0.5, 0]
    p.write_text(json.dumps({"camera0000": {"K": [[1]], "R": [], "T": []}}))
    with pytest.raises(UserError, match="camera0000"):
        ring.read_cameras_json(p)
    p.write_bytes(b"\xff\xfe")
    with pytest.raises(UserError, match="not valid JSON"):
        ring.read_cameras_json(p)


def test_bike_folder_reads_and_writes_views(tmp_path):
    with pytest.raises(UserError, match="bike folder not found"):
        bike_folder.read_meta(tmp_path / "nope")
    (tmp_path / "keypoints.json").write_text(json.dumps({"keypoints": {"seat": [0, 1, "a"]}}))
    with pytest.raises(UserError, match="seat"):
        bike_folder.read_keypoints(tmp_path)
    rgba = np.zeros((4, 5, 4), np.uint8)
    rgba[1:3, 1:4] = (200, 100, 50, 255)
    rgba[0, 0] = (255, 255, 255, 100)  # alpha < 0.5: outside the mask
    paths = bike_folder.write_view(str(tmp_path / "views"), "camera0000", rgba=rgba)
    assert bike_folder.view_complete(paths)
    from PIL import Image
    mask = np.asarray(Image.open(paths["mask"]))
    assert mask.sum() == 255 * 6 and mask[0, 0] == 0
    assert (np.asarray(Image.open(paths["rgba"])) == rgba).all()

"""Frame conversion and the 36-view ring against docs/contract.md, numbers derived by hand."""
import math

import numpy as np
import pytest

from addon.core import frames
from cyclist_formats import ring


def test_canonical_to_blender_axes():
    # canonical X forward, Y up, Z rider's right -> Blender x forward, z up, -y right
    assert np.allclose(frames.to_blender([1, 0, 0]), [1, 0, 0])
    assert np.allclose(frames.to_blender([0, 1, 0]), [0, 0, 1])
    assert np.allclose(frames.to_blender([0, 0, 1]), [0, -1, 0])
    assert np.isclose(np.linalg.det(frames.C), 1.0)
    p = np.random.default_rng(0).normal(size=(10, 3))
    assert np.allclose(frames.to_canonical(frames.to_blender(p)), p)


def test_matrix_conversion_is_the_same_motion():
    rng = np.random.default_rng(1)
    a = rng.normal(size=3)
    R = _rodrigues(a / np.linalg.norm(a), 0.7)
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, rng.normal(size=3)
    p = rng.normal(size=3)
    moved_c = M[:3, :3] @ p + M[:3, 3]
    Mb = frames.matrix_to_blender(M)
    moved_b = Mb[:3, :3] @ frames.to_blender(p) + Mb[:3, 3]
    assert np.allclose(frames.to_canonical(moved_b), moved_c)
    assert np.allclose(frames.matrix_to_canonical(Mb), M)


def _rodrigues(axis, angle):
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


@pytest.mark.parametrize("h", [0.0, 0.55])
def test_ring_geometry(h):
    cams = ring.ring([0.0, h, 0.0])
    names = [k for k in cams if k.startswith("camera")]
    assert len(names) == 36 and cams["orbit_centre"] == [0.0, h, 0.0]
    for i, n in enumerate(names):
        R, T, K = (np.array(cams[n][k]) for k in ("R", "T", "K"))
        centre = -R.T @ T
        assert np.isclose(np.linalg.norm(centre - [0, h, 0]), 12.0)
        assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1)
        assert np.allclose(K, [[2084.97, 0, 256], [0, 2084.97, 256], [0, 0, 1]])
        # the optical axis (+z_cam) points at the orbit centre
        assert np.allclose(R[2], ([0, h, 0] - centre) / 12.0)
        # camera y (image down) is world down: no roll, no elevation
        assert np.allclose(R[1], [0, -1, 0])
        # azimuth: centre is rotated by +10 deg * i about +Y (right-hand)
        a = math.radians(10 * i)
        assert np.allclose(centre - [0, h, 0], [-12 * math.sin(a), 0, -12 * math.cos(a)])
    R0 = np.array(cams["camera0000"]["R"])
    assert np.allclose(R0, np.diag([-1, -1, 1]))


def test_view0_sees_left_side_front_on_left_and_view9_from_behind():
    cams = ring.ring([0.0, 0.5, 0.0])
    c0 = cams["camera0000"]
    front, rear = np.array([[0.5, 0.35, 0.0]]), np.array([[-0.5, 0.35, 0.0]])
    uf = ring.project(front, c0["K"], c0["R"], c0["T"])[0]
    ur = ring.project(rear, c0["K"], c0["R"], c0["T"])[0]
    assert uf[0] < 256 < ur[0]  # front wheel on the image's left
    high = ring.project(np.array([[0, 1.0, 0]]), c0["K"], c0["R"], c0["T"])[0]
    assert high[1] < 256  # up is image-up
    c9 = cams["camera0009"]
    centre9 = -np.array(c9["R"]).T @ np.array(c9["T"])
    assert np.allclose(centre9, [-12, 0.5, 0])  # behind the bike, looking forward (+X)
    assert np.allclose(np.array(c9["R"])[2], [1, 0, 0])
    # from behind, the rider's right (+Z) is on the image's right
    right = ring.project(np.array([[0, 0.5, 0.3]]), c9["K"], c9["R"], c9["T"])[0]
    assert right[0] > 256


def test_transforms_json_is_nerf_convention():
    cams = ring.ring([0.0, 0.4, 0.0])
    tj = ring.transforms_json(cams)
    assert math.isclose(tj["camera_angle_x"], 2 * math.atan(256 / 2084.97))
    for f, n in zip(tj["frames"], sorted(k for k in cams if k.startswith("camera"))):
        M = np.array(f["transform_matrix"])
        R, T = np.array(cams[n]["R"]), np.array(cams[n]["T"])
        assert np.allclose(M[:3, 3], -R.T @ T)
        # OpenGL camera looks along its -z: -M[:3,2] is the viewing direction = R[2]
        assert np.allclose(-M[:3, 2], R[2])
        assert f["file_path"] == f"./rgba/{n}/0000"


def test_torch_ring_matches_blender_ring():
    torch = pytest.importorskip("torch")
    from splatting.raster.camera import ring_camera

    cams = ring.ring([0.0, 0.6, 0.0])
    for i in (0, 5, 9, 27, 35):
        c = ring_camera(10 * i, (0.0, 0.6, 0.0), dtype=torch.float64)
        n = f"camera{i:04d}"
        assert np.allclose(c.R.numpy(), cams[n]["R"]) and np.allclose(c.T.numpy(), cams[n]["T"])
        assert np.allclose(c.K.numpy(), cams[n]["K"])

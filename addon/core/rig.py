"""The 36-view camera ring of DESIGN.md, in the canonical frame (numpy only, no bpy).

OpenCV world-to-camera: x_cam = R @ X + T; +z forward, +y image-down, +x image-right.
View 0 sits at orbit_centre + (0, 0, -12) looking along +Z (R0 = diag(-1, -1, 1)); view i is
view 0 rotated about the vertical axis through the orbit centre by +step*i (right-hand, +Y).
The torch side has the same ring in splatting/cameras.py; tests/test_render_views.py checks
that the two agree through cameras.json.
"""
import math

import numpy as np

SIZE = 512
FOCAL = 2084.97
DISTANCE = 12.0
N_VIEWS = 36
STEP_DEG = 10.0
R0 = np.diag([-1.0, -1.0, 1.0])


def intrinsics(size=SIZE, focal=FOCAL):
    return np.array([[focal, 0.0, size / 2], [0.0, focal, size / 2], [0.0, 0.0, 1.0]])


def rot_y(deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def view(i, orbit_centre, step_deg=STEP_DEG, distance=DISTANCE):
    """(R, T, centre) of ring view i around orbit_centre (canonical frame)."""
    Ry = rot_y(step_deg * i)
    R = R0 @ Ry.T
    centre = np.asarray(orbit_centre, float) + Ry @ np.array([0.0, 0.0, -distance])
    return R, -R @ centre, centre


def ring(orbit_centre, n=N_VIEWS, step_deg=STEP_DEG, distance=DISTANCE, size=SIZE, focal=FOCAL):
    """The SHERF cameras.json dict for the ring: {"camera0000": {"K","R","T"}, ..., "orbit_centre"}."""
    K = intrinsics(size, focal)
    cams = {}
    for i in range(n):
        R, T, _ = view(i, orbit_centre, step_deg, distance)
        cams[f"camera{i:04d}"] = {"K": K.tolist(), "R": R.tolist(), "T": T.tolist()}
    cams["orbit_centre"] = [float(v) for v in orbit_centre]
    return cams


def camera_to_world_opengl(R, T):
    """4x4 camera-to-world with OpenGL/Blender camera axes (looks along -z, +y up): NeRF's convention."""
    R = np.asarray(R, float)
    M = np.eye(4)
    M[:3, :3] = R.T @ np.diag([1.0, -1.0, -1.0])
    M[:3, 3] = -R.T @ np.asarray(T, float)
    return M


def project(points, K, R, T):
    """Canonical points (N, 3) -> pixel coordinates (N, 2) (continuous; pixel centres at +0.5)."""
    x = np.asarray(points, float) @ np.asarray(R, float).T + np.asarray(T, float)
    uv = x @ np.asarray(K, float).T
    return uv[:, :2] / uv[:, 2:3]


def transforms_json(cams, size=SIZE, focal=FOCAL, file_pattern="./rgba/{name}/0000"):
    """NeRF-synthetic transforms.json (camera_angle_x + per-frame camera-to-world, OpenGL axes)."""
    frames = []
    for name in sorted(k for k in cams if k.startswith("camera")):
        c = cams[name]
        frames.append({"file_path": file_pattern.format(name=name),
                       "transform_matrix": camera_to_world_opengl(c["R"], c["T"]).tolist()})
    return {"camera_angle_x": 2 * math.atan(size / (2 * focal)), "fl_x": focal, "fl_y": focal,
            "cx": size / 2, "cy": size / 2, "w": size, "h": size, "frames": frames}

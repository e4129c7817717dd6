"""The 36-view camera ring and cameras.json (docs/contract.md "Cameras"), numpy only.

OpenCV world-to-camera: x_cam = R @ X + T; +z forward, +y image-down, +x image-right; pixel
centres at +0.5.  View 0 sits at orbit_centre + (0, 0, -12) looking along +Z (R0 = diag(-1, -1, 1));
view i is view 0 rotated about the vertical axis through the orbit centre by +step*i (right-hand,
+Y).  `orbit_view` adds an elevation (the cyclist and dataset cameras); at elevation 0 it is the
ring.  Both worlds build cameras here: the Blender renderers and splatting.raster.camera.
"""
import math

import numpy as np

from .bike_folder import read_json
from .errors import UserError

SIZE = 512
FOCAL = 2084.97
DISTANCE = 12.0
N_VIEWS = 36
STEP_DEG = 10.0
R0 = np.diag([-1.0, -1.0, 1.0])


def camera_name(i):
    return f"camera{i:04d}"


def intrinsics(size=SIZE, focal=FOCAL, height=None):
    """Pinhole K with the principal point at the image centre (width `size`, height `height`)."""
    h = size if height is None else height
    return np.array([[focal, 0.0, size / 2], [0.0, focal, h / 2], [0.0, 0.0, 1.0]])


def focal_for(size):
    """The ring's focal length scaled to an image `size` pixels wide (same field of view)."""
    return FOCAL * size / SIZE


def rot_y(deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def view(i, orbit_centre, step_deg=STEP_DEG, distance=DISTANCE):
    """(R, T, centre) of ring view i around orbit_centre (canonical frame)."""
    return azimuth_view(step_deg * i, orbit_centre, distance)


def azimuth_view(azimuth_deg, orbit_centre, distance=DISTANCE):
    """(R, T, centre) of view 0 turned by azimuth_deg about the vertical axis through orbit_centre."""
    Ry = rot_y(azimuth_deg)
    R = R0 @ Ry.T
    centre = np.asarray(orbit_centre, float) + Ry @ np.array([0.0, 0.0, -distance])
    return R, -R @ centre, centre


def orbit_view(azimuth_deg, elevation_deg=0.0, distance=DISTANCE, centre=(0.0, 0.0, 0.0)):
    """(R, T, camera centre) of a camera looking at `centre` from `distance`, turned by azimuth
    about +Y and raised by elevation (camera above the centre when positive).  Azimuth a and
    elevation 0 is the ring's view at a (up to float rounding)."""
    a, e = math.radians(azimuth_deg), math.radians(elevation_deg)
    c = np.asarray(centre, float)
    # view 0's offset (0, 0, -d) tilted up by e, then turned about +Y by a
    off = np.array([-distance * math.cos(e) * math.sin(a), distance * math.sin(e),
                    -distance * math.cos(e) * math.cos(a)])
    fwd = -off / np.linalg.norm(off)
    right = np.cross(fwd, [0.0, 1.0, 0.0])
    right = right / np.linalg.norm(right)
    down = np.cross(fwd, right)
    R = np.stack([right, down, fwd])
    return R, -R @ (c + off), c + off


def ring(orbit_centre, n=N_VIEWS, step_deg=STEP_DEG, distance=DISTANCE, size=SIZE, focal=FOCAL):
    """The SHERF cameras.json dict for the ring: {"camera0000": {"K","R","T"}, ..., "orbit_centre"}."""
    K = intrinsics(size, focal)
    cams = {}
    for i in range(n):
        R, T, _ = view(i, orbit_centre, step_deg, distance)
        cams[camera_name(i)] = {"K": K.tolist(), "R": R.tolist(), "T": T.tolist()}
    cams["orbit_centre"] = [float(v) for v in orbit_centre]
    return cams


def read_cameras_json(path):
    """cameras.json -> ({name: (K 3x3, R 3x3, T 3) float64 arrays} sorted by name, orbit_centre or None).

    Every malformed case is one UserError naming the file (and the camera)."""
    data = read_json(path, "cameras.json", missing=f"no cameras file: {path}")
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected an object of cameras (camera0000, camera0001, ...)")
    cams = {}
    for name in sorted(k for k in data if k.startswith("camera")):
        d = data[name]
        try:
            K = np.asarray(d["K"], dtype=np.float64).reshape(3, 3)
            R = np.asarray(d["R"], dtype=np.float64).reshape(3, 3)
            T = np.asarray(d["T"], dtype=np.float64).reshape(3)
        except (KeyError, TypeError, ValueError) as e:
            raise UserError(f"{path}: camera {name} needs K (3x3), R (3x3), T (3): {e}") from None
        if not (np.isfinite(K).all() and np.isfinite(R).all() and np.isfinite(T).all()):
            raise UserError(f"{path}: camera {name} has non-finite values")
        cams[name] = (K, R, T)
    if not cams:
        raise UserError(f"{path}: no cameras (expected keys camera0000, camera0001, ...)")
    return cams, data.get("orbit_centre")


def camera_entry(path, name):
    """One camera of a cameras.json by name -> (K, R, T); UserError listing a few names if unknown."""
    cams, _ = read_cameras_json(path)
    if name not in cams:
        raise UserError(f"{path} has no camera '{name}' (it has {', '.join(list(cams)[:3])}, ...)")
    return cams[name]


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


def transforms_json(cams, size=SIZE, focal=FOCAL, file_pattern="./rgba/{name}/0000", height=None):
    """NeRF-synthetic transforms.json (camera_angle_x + per-frame camera-to-world, OpenGL axes)."""
    h = size if height is None else height
    frames = []
    for name in sorted(k for k in cams if k.startswith("camera")):
        c = cams[name]
        frames.append({"file_path": file_pattern.format(name=name),
                       "transform_matrix": camera_to_world_opengl(c["R"], c["T"]).tolist()})
    return {"camera_angle_x": 2 * math.atan(size / (2 * focal)), "fl_x": focal, "fl_y": focal,
            "cx": size / 2, "cy": h / 2, "w": size, "h": h, "frames": frames}

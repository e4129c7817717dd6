"""Camera presets: the paper's object-centred ring and the driving cameras perception data comes from.

A driving camera stands in the street world: the road is the plane Y = 0 (canonical axes, Y up),
the camera centre is at (0, height_m, 0) and, at pitch = roll = 0, it looks along world +Z with
image-right = world -X and image-down = world -Y (the ring's view 0 rotation, diag(-1, -1, 1)).
Pitch turns it about its own x axis (positive = nose down, towards the road), roll about its
optical axis (x_cam = Rz(roll) x, so a level horizon appears turned by -roll in the image).  Intrinsics are OpenCV's pinhole K with pixel
centres at +0.5, principal point anywhere (KITTI's is off centre), non-square images.

Values (rounded as the datasets publish them; the table is config_models.CAMERA_PRESETS, the camera
block's defaults, and resolve() is config_models.resolve_camera):
- kitti: KITTI object benchmark, left colour camera P2 of the 2011_09_26 calibration: 1242x375,
  fx = fy = 721.5377, (cx, cy) = (609.5593, 172.854); mounted 1.65 m above the road.
- nuscenes: nuScenes CAM_FRONT: 1600x900, fx = fy = 1266.4, (cx, cy) = (816.3, 491.5); ~1.51 m.
- waymo: Waymo Open FRONT: 1920x1280, fx = fy = 2055.6, (cx, cy) = (939.7, 641.1); ~2.1 m.
- dashcam: a generic 1920x1080 dash camera with 90 deg horizontal field of view (fx = 960),
  centred principal point, 1.3 m.
- custom: every field from the config.
`scale` renders any preset at a fraction of its resolution (K scaled with it).
"""
import math

import numpy as np

# the camera block's fields, presets and resolve() live with the config's models (torch-free)
from splatting.dataset.config_models import resolve_camera as resolve  # noqa: F401 (callers use camera_presets.resolve)
from splatting.raster.camera import from_numpy

R0 = np.diag([-1.0, -1.0, 1.0])  # level camera looking along +Z (ring view 0)


def intrinsics(c):
    return np.array([[c["fx"], 0.0, c["cx"]], [0.0, c["fy"], c["cy"]], [0.0, 0.0, 1.0]])


def tilt(c):
    """Rotation from the level camera frame to the pitched and rolled one (camera axes)."""
    p, r = math.radians(c["pitch_deg"]), math.radians(c["roll_deg"])
    # nose down: the level-frame direction (0, sin p, cos p) (p below the horizon) becomes the axis
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(p), -math.sin(p)], [0.0, math.sin(p), math.cos(p)]])
    Rz = np.array([[math.cos(r), -math.sin(r), 0.0], [math.sin(r), math.cos(r), 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Rx


def level_pose(c):
    """(R, T) world -> level camera (the KITTI rectified frame: gravity along +y)."""
    centre = np.array([0.0, c["height_m"], 0.0])
    return R0, -R0 @ centre


def pose(c):
    """(R, T) world -> camera, OpenCV convention (x_cam = R X + T)."""
    Rl, Tl = level_pose(c)
    Rt = tilt(c)
    return Rt @ Rl, Rt @ Tl


def street_camera(c, name=""):
    """splatting.raster.camera.Camera of a resolved driving-camera spec."""
    R, T = pose(c)
    return from_numpy(intrinsics(c), R, T, c["width"], c["height"], name)


def project(points, c):
    """(n, 3) world points -> (uv (n, 2), z (n,)) with plain numpy (pixel centres at +0.5)."""
    R, T = pose(c)
    x = np.asarray(points, float) @ R.T + T
    z = x[:, 2]
    K = intrinsics(c)
    zs = np.where(z > 1e-9, z, 1.0)
    return np.column_stack([K[0, 0] * x[:, 0] / zs + K[0, 2], K[1, 1] * x[:, 1] / zs + K[1, 2]]), z

"""KITTI object format (`labels.formats: [kitti]`): DIR/kitti/training/{image_2, label_2, calib}/%06d
and DIR/kitti/ImageSets/{train,trainval}.txt, next to the COCO output.

Rectified frame: KITTI's labels live in a level camera frame (y along gravity, down).  Ours is the
camera's own frame turned about its x axis (and optical axis) until level: the same camera centre,
x = the camera's right projected on the road plane, y = world down (-Y), z = x cross y.  The
driving presets at pitch = roll = 0 are level, so there it is the camera frame and P2 = K [I | 0];
a pitched camera (and the ring's raised views) gets P2 = K [R_tilt | 0], which still projects
rectified points to pixels as every KITTI tool assumes (P2 @ [x, y, z, 1]).
calib: P0 = P1 = P2 = P3 (one camera, no stereo baseline), R0_rect = I, Tr_velo_to_cam = a
virtual lidar at the camera centre with KITTI's velodyne axes (x forward, y left, z up),
Tr_imu_to_velo = [I | 0] (no IMU).
label_2 fields (KITTI devkit readme): type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y
- type: `Cyclist` for rider + bicycle (and rider + scooter); `Misc` for motorcyclists and riderless
  bikes (KITTI has neither a bicycle nor a motorcyclist class).  Pedestrian is never used for riders.
- truncated: share of the projected extent outside the image (0..1); occluded: 0 fully visible,
  1 partly, 2 largely (from the visible share of the amodal mask);
- bbox: the amodal 2D box clipped to the image (KITTI boxes cover occluded parts too);
- h, w, l: the posed rider + bike extent in the instance's heading frame (metres);
- x, y, z: bottom centre of the 3D box in rectified camera coordinates; rotation_y: the heading
  about the rectified y axis (0 = facing camera +x); alpha = rotation_y - atan2(x, z), wrapped.
"""
import math
import os
import shutil

import numpy as np

from cyclist_formats import kitti_frame
from cyclist_formats.atomic import atomic_path
from cyclist_formats.errors import UserError
from cyclist_formats.kitti_frame import FIELDS, calib_text, label_line  # noqa: F401  (the format lives there)

KITTI_TYPES = {"cyclist": "Cyclist", "motorcyclist": "Misc", "parked": "Misc"}


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def rect_frame(R, T):
    """(R_rect (3, 3) world -> rectified, centre (3,), R_tilt (3, 3) rectified -> camera)."""
    R = np.asarray(R, float)
    centre = -R.T @ np.asarray(T, float)
    right = R[0].copy()
    right[1] = 0.0
    if np.linalg.norm(right) < 1e-9:  # looking straight down: keep the camera's y for the heading
        right = np.cross(R[1], [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.array([0.0, -1.0, 0.0])
    Rr = np.stack([right, down, np.cross(right, down)])
    return Rr, centre, R @ Rr.T


def calib(K, R, T):
    """{name: flat list} of the calib file."""
    _, _, Rt = rect_frame(R, T)
    P = np.asarray(K, float) @ np.column_stack([Rt, np.zeros(3)])
    velo = np.array([[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0]])
    return {"P0": P, "P1": P, "P2": P, "P3": P, "R0_rect": np.eye(3), "Tr_velo_to_cam": velo,
            "Tr_imu_to_velo": np.column_stack([np.eye(3), np.zeros(3)])}


def box3d(R, T, box):
    """Instance 3D box (world: bottom centre, heading_deg, (h, w, l)) -> KITTI location, rotation_y, alpha."""
    Rr, centre, _ = rect_frame(R, T)
    loc = Rr @ (np.asarray(box["bottom_centre"], float) - centre)
    a = math.radians(box["heading_deg"])
    d = Rr @ np.array([math.cos(a), 0.0, -math.sin(a)])  # the bike's forward, rectified
    ry = math.atan2(-d[2], d[0])
    alpha = wrap(ry - math.atan2(loc[0], loc[2]))
    return loc, ry, alpha


def corners(h, w, l, loc, ry):
    """8 corners (3, 8) of a KITTI box (devkit's compute_box_3d)."""
    c, s = math.cos(ry), math.sin(ry)
    Ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    x = [l / 2, l / 2, -l / 2, -l / 2, l / 2, l / 2, -l / 2, -l / 2]
    y = [0, 0, 0, 0, -h, -h, -h, -h]
    z = [w / 2, -w / 2, -w / 2, w / 2, w / 2, -w / 2, -w / 2, w / 2]
    return Ry @ np.array([x, y, z]) + np.asarray(loc, float)[:, None]


def project_rect(P, pts):
    """(3, n) rectified points -> (2, n) pixels with the 3x4 P."""
    h = np.asarray(P) @ np.vstack([pts, np.ones(pts.shape[1])])
    return h[:2] / h[2]


def parse_label_line(line):
    """A label_2 line -> {field: value} (KITTI's documented 15 fields; a 16th score is allowed);
    ValueError when malformed (cyclist_formats.kitti_frame checks the fields)."""
    try:
        return kitti_frame.parse_label_line(line)
    except UserError as e:
        raise ValueError(str(e)) from None


def kitti_paths(out_dir, index):
    base = os.path.join(out_dir, "kitti", "training")
    return {"image": os.path.join(base, "image_2", f"{index:06d}.png"),
            "label": os.path.join(base, "label_2", f"{index:06d}.txt"),
            "calib": os.path.join(base, "calib", f"{index:06d}.txt")}


def link_or_copy(src, dst):
    """`dst` (atomic) a hard link to `src` where the file system allows, else a copy."""
    os.makedirs(os.path.dirname(dst), exist_ok=True)
    with atomic_path(dst) as tmp:
        os.remove(tmp)  # temp_name made the file; os.link needs the name free
        try:
            os.link(src, tmp)
        except OSError:
            shutil.copyfile(src, tmp)


def write_sample(out_dir, index, image_path, objects, calib_dict):
    """Image (hard link to the COCO image where the file system allows, else a copy), label, calib."""
    p = kitti_paths(out_dir, index)
    for k in ("image", "label", "calib"):
        os.makedirs(os.path.dirname(p[k]), exist_ok=True)
    link_or_copy(image_path, p["image"])
    with atomic_path(p["calib"]) as tmp:
        with open(tmp, "w") as f:
            f.write(calib_text(calib_dict))
    with atomic_path(p["label"]) as tmp:
        with open(tmp, "w") as f:
            f.write("".join(label_line(o) for o in objects))


def sample_done(out_dir, index):
    return all(os.path.isfile(v) for v in kitti_paths(out_dir, index).values())


def write_imagesets(out_dir, count):
    d = os.path.join(out_dir, "kitti", "ImageSets")
    os.makedirs(d, exist_ok=True)
    text = "".join(f"{i:06d}\n" for i in range(count))
    for name in ("train.txt", "trainval.txt"):
        with atomic_path(os.path.join(d, name)) as tmp:
            with open(tmp, "w") as f:
                f.write(text)

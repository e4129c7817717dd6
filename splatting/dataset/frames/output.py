"""The KITTI side of a frames-mode sample: DIR/kitti/training/{image_2, label_2, calib, planes, velodyne}.

- image_2: the augmented image (a hard link to the COCO image where the file system allows);
- calib, planes: the frame's own files, byte for byte (a frame without planes/ gets the plane the
  insertion used: fitted to its LiDAR or the camera-height fallback, in the planes layout);
- label_2: the frame's own lines, every byte kept except a raised `occluded` (frames.occlusion),
  followed by one line per inserted instance (Cyclist; Misc for parked bikes and motorcyclists);
- velodyne: the frame's scan with the inserted cyclists in it (lidar.insert_into_scan), when the
  frame has one and LiDAR use is on.
Every file is written atomically; the sample's shard, written after them, marks it complete.
"""
import os
import shutil

from cyclist_formats import kitti_frame
from cyclist_formats.atomic import atomic_path
from splatting.dataset import kitti

SUBDIRS = ("image_2", "label_2", "calib", "planes", "velodyne")


def paths(out_dir, index):
    base = os.path.join(out_dir, "kitti", "training")
    return {d: os.path.join(base, d, f"{index:06d}" + (".bin" if d == "velodyne" else ".png" if d == "image_2" else ".txt"))
            for d in SUBDIRS}


def _copy(src, dst):
    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def _text(dst, text):
    with atomic_path(dst) as tmp:
        with open(tmp, "w") as f:
            f.write(text)


def write_sample(out_dir, index, image_path, objects, fx):
    """fx: extras["frame"] of make_sample (FrameSample.kitti_extras)."""
    p = paths(out_dir, index)
    for k in SUBDIRS:
        os.makedirs(os.path.dirname(p[k]), exist_ok=True)
    kitti.link_or_copy(image_path, p["image_2"])
    src = kitti_frame.frame_paths(fx["folder"], fx["frame_id"])
    _copy(src["calib"], p["calib"])
    if os.path.isfile(src["plane"]):
        _copy(src["plane"], p["planes"])
    else:
        _text(p["planes"], kitti_frame.plane_text(fx["plane"]))
    if fx.get("scan") is not None:
        with atomic_path(p["velodyne"]) as tmp:
            fx["scan"].astype("<f4").tofile(tmp)
    _text(p["label_2"], "".join(line + "\n" for line in fx["frame_lines"]) + "".join(kitti.label_line(o) for o in objects))

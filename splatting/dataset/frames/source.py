"""The input frames: a KITTI object folder, checked once per process, and one frame's data.

The road plane of a frame, in this order: its planes/ID.txt; else a RANSAC plane fitted to its
LiDAR points (lidar.fit_ground_plane, seeded by the frame id so it is the same in every worker);
else a level road `insert.camera_height_m` below camera 0.  Which one was used is recorded.
"""
import os
import zlib

import numpy as np

from cyclist_formats import kitti_frame
from cyclist_formats.errors import UserError
from splatting import paths
from splatting.dataset.frames import lidar
from splatting.dataset.frames.road import Road, boxes_of

_FOLDERS = {}


def locate(folder):
    """The frames folder as configured: as given (relative to the working directory), else relative to
    the repository root (the preset's ../shared/realism/kitti_dev), else relative to the root's
    parent (a worktree beside the main checkout).  -> absolute path, or UserError."""
    if not isinstance(folder, str) or not folder:
        raise UserError("config field 'frames': frames mode needs a KITTI object folder (or --frames DIR)")
    cands = [folder] if os.path.isabs(folder) else [folder, os.path.join(str(paths.ROOT), folder),
                                                     os.path.join(str(paths.ROOT), "..", folder)]
    for c in cands:
        if os.path.isdir(c):
            return os.path.abspath(c)
    raise UserError(f"config field 'frames': no such folder {folder!r}")


def development_frames():
    """The shared development frames (the repository's sibling shared/realism/kitti_dev, or a
    worktree's grand-parent's), or None."""
    for c in (os.path.join(str(paths.ROOT), "..", "shared", "realism", "kitti_dev"),
              os.path.join(str(paths.ROOT), "..", "..", "shared", "realism", "kitti_dev")):
        if os.path.isdir(os.path.join(c, "image_2")):
            return os.path.abspath(c)
    return None


def open_folder(folder):
    """{id: record} of kitti_frame.check_folder, once per process and folder."""
    folder = os.path.abspath(folder)
    if folder not in _FOLDERS:
        _FOLDERS[folder] = kitti_frame.check_folder(folder)
    return _FOLDERS[folder]


def image_size(path):
    """(width, height) from the PNG header."""
    try:
        with open(path, "rb") as f:
            head = f.read(24)
    except OSError as e:
        raise UserError(f"{path}: cannot read ({e.strerror})") from None
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise UserError(f"{path}: not a PNG file")
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def read_image(path):
    from PIL import Image
    try:
        with Image.open(path) as im:
            im = im.convert("RGB")
            return np.asarray(im, dtype=np.uint8).copy()
    except OSError as e:
        raise UserError(f"{path}: cannot be read as an image ({e})") from None


class Frame:
    """One frame: id, calib, labels [(row, text)], boxes, image size, road (Road), plane source,
    scan (N, 4) float32 or None, T_velo_to_rect (4, 4)."""

    def __init__(self, folder, fid, cfg):
        rec = open_folder(folder)[fid]
        self.folder, self.id, self.rec = folder, fid, rec
        self.calib, self.labels = rec["calib"], rec["labels"]
        self.boxes = boxes_of(self.labels)
        self.width, self.height = image_size(rec["image"])
        self.T_velo_to_rect = kitti_frame.velo_to_rect(self.calib)
        use_lidar = cfg.insert.lidar and rec["velodyne"] is not None
        self.scan = kitti_frame.read_velodyne(rec["velodyne"]) if use_lidar else None
        plane, self.plane_source = rec["plane"], "planes"
        if plane is None and self.scan is not None:
            try:
                rng = np.random.default_rng(zlib.crc32(fid.encode()))
                plane, self.plane_source = tuple(lidar.fit_ground_plane(self.scan[:, :3], self.T_velo_to_rect, rng)), "lidar"
            except ValueError:
                plane = None
        if plane is None:
            plane, self.plane_source = (0.0, -1.0, 0.0, float(cfg.insert.camera_height_m)), "camera_height"
        self.road = Road(plane, self.calib["P2"], self.width, self.height)
        self._image, self._stats = None, {}
        if self.scan is not None:  # once per frame: the scan in rect and its points above the road
            self.scan_rect = lidar.velo_to_rect(self.scan[:, :3], self.T_velo_to_rect)
            self.scan_height = lidar.plane_height(self.scan_rect, self.road.plane)

    def stat(self, name, fn):
        """fn(image), once per frame (the blur and noise estimates)."""
        if name not in self._stats:
            self._stats[name] = fn(self.image())
        return self._stats[name]

    def image(self):
        if self._image is None:
            self._image = read_image(self.rec["image"])
            if self._image.shape[:2] != (self.height, self.width):
                raise UserError(f"{self.rec['image']}: decoded size differs from its header")
        return self._image


_CACHE = {}


def frame(cfg, fid):
    """The Frame `fid` of the configured folder (a small per-process cache: a frame is reused by
    several samples in a row when count > number of frames... and by the placement and the render)."""
    key = (cfg.frames, fid, bool(cfg.insert.lidar), float(cfg.insert.camera_height_m))
    if key not in _CACHE:
        if len(_CACHE) >= 4:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = Frame(cfg.frames, fid, cfg)
    return _CACHE[key]


def frame_id(cfg, index):
    """Frame of sample `index`: the folder's frames in turn (index mod their number)."""
    ids = list(open_folder(cfg.frames))
    return ids[index % len(ids)]

"""Occlusion both ways between a frame's real objects and the inserted cyclists.

The frame's depth (camera-2 z per pixel, 0 = unknown) is the nearer of
- its labelled 3D boxes drawn as solid boxes (every type but DontCare: cars, vans, trucks,
  pedestrians, cyclists, trams, misc): a ray per pixel centre from camera 2, slab-intersected with
  each oriented box; where LiDAR is sparse (far, dark or glass surfaces) the boxes still hide;
- the LiDAR depth image when the frame has a scan (lidar.lidar_depth_image: projected and densified
  as docs/kitti_lidar.md describes), which also holds the unlabelled things: poles, walls, trees.
  Points within 0.2 m of the road plane are left out first: on a planar road the road itself can
  hide nothing standing on it, and its densified depth is coarse (at 20 m one image row spans
  ~0.5 m of road), so it would eat tyres and cast shadows.
An inserted pixel is hidden where the frame is nearer by more than `insert.occlusion_margin_m` (the
margin keeps the road under the tyres, at the same depth as the contact, from eating them).
Keypoints are tested against the nearer of the inserted surface and the frame (so a pedal behind a
car's bonnet is occluded even where no cyclist pixel covers it).

The other way: an inserted cyclist raises the `occluded` of a labelled object whose 2D box it
covers -- a pixel of the object's box counts as covered where an inserted instance is visible there
and nearer than the object (its box's depth at that pixel, else its location's z).  The level from
the covered share of the box, KITTI's bands: < 10 % -> 0, < 50 % -> 1 (partly), else 2 (largely);
the new value is max(old, level): insertion never lowers a label's occlusion.  Rows with
occluded = 3 (unknown) and DontCare rows are kept as they are.
"""
import numpy as np

from splatting.cyclist.scene_render import MASK_ALPHA
from splatting.dataset.kitti import corners

LEVELS = (0.10, 0.50)  # covered share bounds of occlusion levels 0 | 1 | 2


def box_depth(road, box, width, height):
    """(crop (h, w) float32 camera-2 z of the box's entry point, 0 where the ray misses; (u0, v0)) of a
    labelled box (type, h, w, l, loc, ry), or None when it is behind the camera or off the image."""
    _, h, w, l, loc, ry = box
    c = corners(h, w, l, loc, ry)
    uv, z = road.project_rect(c.T)
    if (z <= 0.05).all():
        return None
    if (z <= 0.05).any():  # straddles the camera plane: test every pixel
        u0, v0, u1, v1 = 0, 0, width, height
    else:
        u0, v0 = max(int(np.floor(uv[:, 0].min())), 0), max(int(np.floor(uv[:, 1].min())), 0)
        u1, v1 = min(int(np.ceil(uv[:, 0].max())) + 1, width), min(int(np.ceil(uv[:, 1].max())) + 1, height)
    if u1 <= u0 or v1 <= v0:
        return None
    vs, us = np.mgrid[v0:v1, u0:u1]
    Kinv = np.linalg.inv(road.K)
    d = np.stack([us + 0.5, vs + 0.5, np.ones_like(us, dtype=float)], -1) @ Kinv.T  # camera-2 = rect axes, z = 1
    co, si = np.cos(ry), np.sin(ry)
    Ry = np.array([[co, 0, si], [0, 1, 0], [-si, 0, co]])
    centre = np.asarray(loc, float) + [0.0, -h / 2, 0.0]
    o = Ry.T @ (-road.t - centre)  # camera 2's centre in the box's frame
    dl = d @ Ry  # R^T d for row vectors
    half = np.array([l / 2, h / 2, w / 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-half - o) / dl
        t2 = (half - o) / dl
    tn = np.nanmax(np.minimum(t1, t2), -1)
    tf = np.nanmin(np.maximum(t1, t2), -1)
    hit = (tn <= tf) & (tf > 0)
    depth = np.where(hit, np.maximum(tn, 0.0), 0.0).astype(np.float32)  # t along d = camera-2 z (d_z = 1)
    return depth, (u0, v0)


def boxes_depth(road, boxes, width, height):
    """-> (frame depth of the boxes (H, W) float32, 0 = none; [box_depth entry per box])."""
    D = np.zeros((height, width), np.float32)
    per = []
    for b in boxes:
        e = box_depth(road, b, width, height)
        per.append(e)
        if e is None:
            continue
        crop, (u0, v0) = e
        sl = np.s_[v0:v0 + crop.shape[0], u0:u0 + crop.shape[1]]
        cur = D[sl]
        D[sl] = np.where((crop > 0) & ((cur == 0) | (crop < cur)), crop, cur)
    return D, per


def nearer(a, b):
    """Per-pixel min of two depth images where 0 means unknown."""
    return np.where((a > 0) & ((b == 0) | (a < b)), a, b).astype(np.float32)


def occlude(L, D, margin):
    """Hide the inserted pixels of render_scene's layers L where the frame depth D is nearer by more
    than margin (in place: rgb, alpha -> 0, label -> -1); -> (keypoint alpha, keypoint depth, hidden
    (H, W) bool): the layers for keypoint_visibility with the frame's surfaces as occluders."""
    a, dep = L["alpha"], L["depth"]
    known = D > 0
    hidden = known & (a > 0) & (D < dep - margin)
    L["rgb"][hidden] = 0.0
    a[hidden] = 0.0
    L["label"][hidden] = -1
    front = known & ((a <= MASK_ALPHA) | (D < dep))
    kp_alpha = np.where(front, 1.0, a).astype(np.float32)
    kp_depth = np.where(front, D, dep).astype(np.float32)
    return kp_alpha, kp_depth, hidden


def raised_occlusion(rows, per_box, boxes_rows, label, depth, width, height):
    """New occluded values of the frame's label rows.

    rows: [(row dict, text)] of label_2; boxes_rows: for each row, its index into per_box (box_depth
    entries) or None (DontCare); label: the inserted instances' final label image (-1 = none);
    depth: their depth.  -> [(old, new, covered share)] per row."""
    out = []
    seen = label >= 0
    for (row, _), bi in zip(rows, boxes_rows):
        old = row["occluded"]
        if bi is None or old not in (0, 1, 2):
            out.append((old, old, 0.0))
            continue
        x1, y1 = max(int(np.floor(row["x1"])), 0), max(int(np.floor(row["y1"])), 0)
        x2, y2 = min(int(np.ceil(row["x2"])) + 1, width), min(int(np.ceil(row["y2"])) + 1, height)
        if x2 <= x1 or y2 <= y1:
            out.append((old, old, 0.0))
            continue
        obj = np.full((y2 - y1, x2 - x1), row["z"], np.float32)
        e = per_box[bi]
        if e is not None:
            crop, (u0, v0) = e
            # the box's own depth where its rays hit it, inside the 2D box
            ya, yb = max(y1, v0), min(y2, v0 + crop.shape[0])
            xa, xb = max(x1, u0), min(x2, u0 + crop.shape[1])
            if ya < yb and xa < xb:
                c = crop[ya - v0:yb - v0, xa - u0:xb - u0]
                sub = obj[ya - y1:yb - y1, xa - x1:xb - x1]
                obj[ya - y1:yb - y1, xa - x1:xb - x1] = np.where(c > 0, c, sub)
        cov = seen[y1:y2, x1:x2] & (depth[y1:y2, x1:x2] < obj)
        share = float(cov.mean())
        level = 0 if share < LEVELS[0] else 1 if share < LEVELS[1] else 2
        out.append((old, max(old, level), share))
    return out

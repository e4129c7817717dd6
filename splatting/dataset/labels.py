"""Label semantics: categories (as driving datasets use them), their keypoints and OKS sigmas, and the
per-instance COCO annotation with occlusion, truncation, amodal and 3D fields.

Category ids are fixed (names configurable in `labels.names`):
| id | key | default name | what |
| 1 | bicycle | bicycle | the bike of a cyclist, or a riderless (parked) bike; 11 keypoints |
| 2 | rider | person | the person on a rideable; 17 COCO keypoints (or the 24 SMPL joints) |
| 3 | cyclist | cyclist | rider + bicycle, one mask and box (the KITTI / View-of-Delft box) |
| 4 | motorcyclist | motorcyclist | rider + motorcycle |
| 5 | motorcycle | motorcycle | a motorcycle (ridden or parked); the 11 bike keypoints |
| 6 | scooter | scooter | a crankless rideable (kick scooter, balance bike); the 11 bike keypoints |
A bike's vehicle class: meta.json "category" (bicycle | motorcycle | scooter) when present, else
bicycle when it has a crank and scooter when it has none.  A rider + vehicle is `cyclist` for a
bicycle or scooter and `motorcyclist` for a motorcycle (`labels.combined` changes that).
"""
from typing import NamedTuple

from pycocotools import mask as mask_utils
import numpy as np

from splatting.bike.model import KEYPOINTS as BIKE_KEYPOINTS
# the vehicles (and the config's labels.names / labels.combined defaults) live with the config's models
from splatting.dataset.config_models import VEHICLES
from splatting.dataset.person_keypoints import COCO17, COCO17_FLIP, COCO17_SIGMAS, COCO17_SKELETON
from splatting.rider.kinematics import JOINT_NAMES, PARENTS

CATEGORY_KEYS = ("bicycle", "rider", "cyclist", "motorcyclist", "motorcycle", "scooter")
CATEGORY_IDS = {k: i + 1 for i, k in enumerate(CATEGORY_KEYS)}
SUPER = {"bicycle": "vehicle", "rider": "person", "cyclist": "person", "motorcyclist": "person",
         "motorcycle": "vehicle", "scooter": "vehicle"}

BIKE_SKELETON_NAMES = [("seat", "steer_top"), ("steer_top", "steer_bottom"), ("steer_top", "handle_left"),
                       ("steer_top", "handle_right"), ("steer_bottom", "front_axle"), ("seat", "crank_axle"),
                       ("seat", "rear_axle"), ("crank_axle", "rear_axle"), ("crank_axle", "steer_bottom"),
                       ("crank_axle", "pedal_left"), ("crank_axle", "pedal_right"), ("rear_axle", "ground")]
BIKE_FLIP_NAMES = [("handle_left", "handle_right"), ("pedal_left", "pedal_right")]
# OKS sigmas of the 11 bike keypoints (reasoned, docs/labels.md): COCO's scale - 0.025 for points an
# annotator places to a few mm on a face, ~0.1 for hips under clothing.  Wheel axles and the crank
# axle are hub centres (0.05); steering-tube ends, the seat and the ground contact are extended
# parts whose "centre" is a judgement (0.06-0.07); handle ends are small and well defined (0.05);
# pedals are small, move with the crank and are often hidden by the feet (0.07).
BIKE_SIGMAS = {"seat": 0.07, "pedal_left": 0.07, "pedal_right": 0.07, "steer_top": 0.06, "steer_bottom": 0.06,
               "handle_right": 0.05, "handle_left": 0.05, "crank_axle": 0.05, "front_axle": 0.05,
               "rear_axle": 0.05, "ground": 0.06}


def person_schema(kind):
    if kind == "coco17":
        return {"keypoints": list(COCO17), "skeleton": COCO17_SKELETON, "sigmas": list(COCO17_SIGMAS),
                "flip_pairs": COCO17_FLIP, "keypoint_format": "coco17"}
    names = list(JOINT_NAMES)
    idx = {n: i for i, n in enumerate(names)}
    flip = [[idx[n], idx["right_" + n[5:]]] for n in names if n.startswith("left_")]
    # SMPL joints have no published OKS sigmas; hip-like 0.1 (joint centres inside the body)
    return {"keypoints": names, "skeleton": [[p + 1, j + 1] for j, p in enumerate(PARENTS) if p >= 0],
            "sigmas": [0.1] * len(names), "flip_pairs": flip, "keypoint_format": "smpl24"}


def bike_schema():
    bi = {n: i + 1 for i, n in enumerate(BIKE_KEYPOINTS)}
    return {"keypoints": list(BIKE_KEYPOINTS), "skeleton": [[bi[a], bi[b]] for a, b in BIKE_SKELETON_NAMES],
            "sigmas": [BIKE_SIGMAS[n] for n in BIKE_KEYPOINTS],
            "flip_pairs": [[bi[a] - 1, bi[b] - 1] for a, b in BIKE_FLIP_NAMES]}


def categories(labels_cfg, person_kind):
    """The COCO categories under the config's Labels block (its names) and person keypoint kind."""
    names = labels_cfg.names.model_dump()
    out = []
    for key in CATEGORY_KEYS:
        c = {"id": CATEGORY_IDS[key], "name": names[key], "supercategory": SUPER[key], "key": key}
        if key in VEHICLES:
            c.update(bike_schema())
        elif key == "rider":
            c.update(person_schema(person_kind))
        else:
            c.update(keypoints=[], skeleton=[], sigmas=[])
        out.append(c)
    return out


def vehicle_class(meta, override=None):
    if override:
        return override
    cat = (meta or {}).get("category")
    if cat in VEHICLES:
        return cat
    return "bicycle" if (meta or {}).get("has_crank", True) else "scooter"


class BoxMask(NamedTuple):
    """A mask of a width x height image that is False outside one box: the box's pixels (h, w)
    bool and the box's corner.  Street instances cover a small part of a 1600 x 900 image, so
    their masks are built, combined and encoded inside their boxes."""
    crop: np.ndarray
    u0: int
    v0: int

    def full(self, width, height):
        out = np.zeros((height, width), bool)
        h, w = self.crop.shape
        out[self.v0:self.v0 + h, self.u0:self.u0 + w] = self.crop
        return out

    def bbox_xyxy(self):
        """[x0, y0, x1, y1] of the True pixels (pixel edges); None when there is none."""
        cols, rows = np.flatnonzero(self.crop.any(0)), np.flatnonzero(self.crop.any(1))
        if not len(cols):
            return None
        return [float(self.u0 + cols[0]), float(self.v0 + rows[0]), float(self.u0 + cols[-1] + 1),
                float(self.v0 + rows[-1] + 1)]


def rle(mask, width=None, height=None):
    """COCO compressed RLE of a (H, W) bool mask or a BoxMask (with the image's width, height) ->
    (pycocotools RLE, JSON-ready dict).  Column-major runs are counted over the box's columns
    only (full height): the columns left and right of them are one zero run each."""
    if not isinstance(mask, BoxMask):
        height, width = mask.shape
        mask = BoxMask(np.asarray(mask, bool), 0, 0)
    crop = mask.crop
    cols = np.flatnonzero(crop.any(0))
    if len(cols):
        c0, c1 = int(cols[0]), int(cols[-1]) + 1
        strip = np.zeros((c1 - c0, height), bool)  # the columns, transposed: column-major order
        strip[:, mask.v0:mask.v0 + crop.shape[0]] = crop[:, c0:c1].T
        flat = strip.reshape(-1)
        edges = np.flatnonzero(flat[1:] != flat[:-1]) + 1
        runs = np.diff(np.concatenate([[0], edges, [len(flat)]])).tolist()
        if flat[0]:
            runs.insert(0, 0)  # runs alternate zeros, ones, ... starting with zeros
        runs[0] += (mask.u0 + c0) * height
        tail = (width - mask.u0 - c1) * height
        if len(runs) % 2:
            runs[-1] += tail
        elif tail:
            runs.append(tail)
    else:
        runs = [width * height]
    r = mask_utils.frPyObjects({"counts": runs, "size": [height, width]}, height, width)
    return r, {"size": [int(x) for x in r["size"]], "counts": r["counts"].decode("ascii")}


def occlusion_level(visibility):
    """KITTI's occluded: 0 fully visible, 1 partly, 2 largely occluded (3 unknown: not used), from
    the visible share of the amodal pixels inside the image."""
    if visibility >= 0.85:
        return 0
    return 1 if visibility >= 0.5 else 2


def truncation(box, width, height):
    """Share of the (unclipped) box [x0, y0, x1, y1] outside the image."""
    x0, y0, x1, y1 = box
    area = max(x1 - x0, 1e-9) * max(y1 - y0, 1e-9)
    ix = max(0.0, min(x1, width) - max(x0, 0.0))
    iy = max(0.0, min(y1, height) - max(y0, 0.0))
    return float(np.clip(1.0 - ix * iy / area, 0.0, 1.0))


def annotation(key, visible, amodal, extent_box, width, height, keypoints=None, extra=None):
    """One COCO annotation (without id / image_id) or None when no pixel is visible.
    visible, amodal: (H, W) bool or BoxMask; extent_box: the unclipped projected extent [x0, y0, x1, y1];
    keypoints (n, 3) [x, y, v] or None (the category has none)."""
    if not (visible.crop if isinstance(visible, BoxMask) else visible).any():
        return None
    r, seg = rle(visible, width, height)
    ra, seg_a = rle(amodal, width, height)
    area, area_a = float(mask_utils.area(r)), float(mask_utils.area(ra))
    vis = area / area_a if area_a > 0 else 1.0
    ann = {"category_id": CATEGORY_IDS[key], "iscrowd": 0, "segmentation": seg, "area": area,
           "bbox": [float(x) for x in mask_utils.toBbox(r)],
           "segmentation_amodal": seg_a, "area_amodal": area_a, "bbox_amodal": [float(x) for x in mask_utils.toBbox(ra)],
           "visibility": round(min(vis, 1.0), 4), "occlusion": occlusion_level(vis),
           "truncation": round(truncation(extent_box, width, height), 4)}
    flat, n = [], 0
    if keypoints is not None:
        for x, y, v in np.asarray(keypoints, dtype=np.float64):
            flat += [0.0, 0.0, 0] if v == 0 else [round(float(x), 2), round(float(y), 2), int(v)]
            n += int(v > 0)
    ann["keypoints"], ann["num_keypoints"] = flat, n
    if extra:
        ann.update(extra)
    return ann

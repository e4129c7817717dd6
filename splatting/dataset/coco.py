"""COCO layout: the final merge of per-sample shards into annotations.json (categories, keypoint
schemas and sigmas: splatting.dataset.labels; the fields of an annotation: docs/labels.md).

Keypoint visibility follows COCO: 0 not labelled (outside the image), 1 labelled but occluded,
2 visible.  Masks are the visible pixels (modal), RLE-encoded by pycocotools; the amodal ones sit
beside them in `segmentation_amodal`.  `instance()` is the older single-mask helper (ring sets).
"""
import json
import os

from pycocotools import mask as mask_utils
import numpy as np

from cyclist_formats.atomic import atomic_path
from splatting.bike.model import KEYPOINTS as BIKE_KEYPOINTS
from splatting.rider.kinematics import JOINT_NAMES, PARENTS

BIKE_SKELETON_NAMES = [("seat", "steer_top"), ("steer_top", "steer_bottom"), ("steer_top", "handle_left"),
                       ("steer_top", "handle_right"), ("steer_bottom", "front_axle"), ("seat", "crank_axle"),
                       ("seat", "rear_axle"), ("crank_axle", "rear_axle"), ("crank_axle", "steer_bottom"),
                       ("crank_axle", "pedal_left"), ("crank_axle", "pedal_right"), ("rear_axle", "ground")]
CATEGORY_IDS = {"bicycle": 1, "person": 2, "cyclist": 3}


def categories():
    bi = {n: i + 1 for i, n in enumerate(BIKE_KEYPOINTS)}  # COCO skeletons are 1-based
    return [
        {"id": 1, "name": "bicycle", "supercategory": "vehicle", "keypoints": list(BIKE_KEYPOINTS),
         "skeleton": [[bi[a], bi[b]] for a, b in BIKE_SKELETON_NAMES]},
        {"id": 2, "name": "person", "supercategory": "person", "keypoints": list(JOINT_NAMES),
         "skeleton": [[p + 1, j + 1] for j, p in enumerate(PARENTS) if p >= 0], "keypoint_format": "smpl24"},
        {"id": 3, "name": "cyclist", "supercategory": "person", "keypoints": [], "skeleton": []},
    ]


def instance(mask, category, keypoints=None):
    """Binary mask (H, W) bool, category name, keypoints (n, 3) [x, y, v] or None -> COCO annotation
    without id/image_id, or None when the mask is empty."""
    if not mask.any():
        return None
    rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
    ann = {"category_id": CATEGORY_IDS[category], "iscrowd": 0,
           "segmentation": {"size": [int(x) for x in rle["size"]], "counts": rle["counts"].decode("ascii")},
           "area": float(mask_utils.area(rle)), "bbox": [float(x) for x in mask_utils.toBbox(rle)]}
    if keypoints is not None:
        kp = np.asarray(keypoints, dtype=np.float64)
        flat = []
        for x, y, v in kp:
            flat += [0.0, 0.0, 0] if v == 0 else [round(float(x), 2), round(float(y), 2), int(v)]
        ann["keypoints"] = flat
        ann["num_keypoints"] = int((kp[:, 2] > 0).sum())
    return ann


def merge(out_dir, count, info, cats=None):
    """shards/%06d.json for 0..count-1 -> annotations.json (atomic); ids in sample order."""
    images, anns = [], []
    for i in range(count):
        with open(os.path.join(out_dir, "shards", f"{i:06d}.json")) as f:
            shard = json.load(f)
        images.append(shard["image"])
        for a in shard["annotations"]:
            a = dict(a, id=len(anns) + 1, image_id=shard["image"]["id"])
            anns.append(a)
    doc = {"info": info, "licenses": [], "images": images, "annotations": anns, "categories": cats if cats is not None else categories()}
    path = os.path.join(out_dir, "annotations.json")
    with atomic_path(path) as tmp:
        with open(tmp, "w") as f:
            json.dump(doc, f, separators=(",", ":"))
    return path

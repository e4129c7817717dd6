"""Labels (issue 13): COCO-17 person points from mesh vertices, sigmas in every keypoint category,
the standard COCOeval runs for bbox, segm and keypoints (person and bicycle) and scores the ground
truth against itself 1.0 (that proves the encoding; boxes, masks and points are checked geometrically
beside it), every annotation carries the fields a loader expects."""
import json
import os

import numpy as np
import pytest

from helpers import RIDER, street_config, write_test_bike

COCO_NAMES = ["nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
              "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip",
              "left_knee", "right_knee", "left_ankle", "right_ankle"]
# cocoeval.py's default kpt_oks_sigmas (x 10 there: .26, .25, ...)
COCO_SIGMAS = np.array([.26, .25, .25, .35, .35, .79, .79, .72, .72, .62, .62, 1.07, 1.07, .87, .87, .89, .89]) / 10.0


@pytest.fixture(scope="module")
def street_set(tmp_path_factory):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    root = tmp_path_factory.mktemp("labels")
    write_test_bike(str(root))
    cfg = validate(street_config(str(root), count=3, labels={"formats": ["coco", "kitti"]},
                                 street={"parked_bikes": [1, 1]}))
    out = str(root / "out")
    generate(cfg, out, log=lambda m: None, progress=False)
    return out


def test_person_category_is_coco17_with_cocos_sigmas_and_skeleton(street_set):
    with open(os.path.join(street_set, "annotations.json")) as f:
        doc = json.load(f)
    cats = {c["name"]: c for c in doc["categories"]}
    p = cats["person"]
    assert p["keypoints"] == COCO_NAMES
    assert np.allclose(p["sigmas"], COCO_SIGMAS)
    assert [16, 14] in p["skeleton"] and [6, 7] in p["skeleton"] and len(p["skeleton"]) == 19
    for c in doc["categories"]:
        assert len(c["sigmas"]) == len(c["keypoints"])
    assert len(cats["bicycle"]["sigmas"]) == 11 and all(0.02 < s < 0.15 for s in cats["bicycle"]["sigmas"])
    names = {c["name"] for c in doc["categories"]}
    assert names == {"bicycle", "person", "cyclist", "motorcyclist", "motorcycle", "scooter"}
    for a in doc["annotations"]:
        for k in ("iscrowd", "area", "bbox", "segmentation", "bbox_amodal", "segmentation_amodal", "visibility",
                  "occlusion", "truncation", "track_id", "num_keypoints", "pose_3d"):
            assert k in a, k
        assert a["num_keypoints"] == sum(1 for v in a["keypoints"][2::3] if v > 0)
        assert a["occlusion"] in (0, 1, 2) and 0 <= a["truncation"] <= 1 and 0 < a["visibility"] <= 1
    parked = [a for a in doc["annotations"] if a["parked"]]
    assert parked and all(a["category_id"] == cats["bicycle"]["id"] for a in parked)


def test_cocoeval_reads_the_encoding_ground_truth_scores_itself_one(street_set):
    """Proves the ENCODING (pycocotools loads our RLEs, boxes, keypoints and sigmas and matches
    each annotation to itself), not that the masks are right: the ground truth is scored against
    itself.  The geometry is checked beside it (test_boxes_enclose_their_masks_and_points_sit_on_them)."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval
    gt = COCO(os.path.join(street_set, "annotations.json"))
    dt = gt.loadRes([dict(a, score=1.0) for a in gt.dataset["annotations"]])
    for iou in ("bbox", "segm"):
        ev = COCOeval(gt, dt, iou)
        ev.evaluate(); ev.accumulate(); ev.summarize()
        assert ev.stats[0] == pytest.approx(1.0), iou
    for name in ("person", "bicycle"):
        cat = gt.loadCats(gt.getCatIds(catNms=[name]))[0]
        ev = COCOeval(gt, dt, "keypoints")  # the snippet of docs/labels.md
        ev.params.catIds = [cat["id"]]
        ev.params.kpt_oks_sigmas = np.array(cat["sigmas"])
        ev.evaluate(); ev.accumulate(); ev.summarize()
        assert ev.stats[0] == pytest.approx(1.0), name


def test_boxes_enclose_their_masks_and_points_sit_on_them(street_set):
    """Geometry, independent of COCOeval: each visible mask's tight box is its bbox, its area the
    pixel count, the amodal mask covers the visible one, and visible keypoints lie in the image."""
    from pycocotools import mask as mu
    with open(os.path.join(street_set, "annotations.json")) as f:
        doc = json.load(f)
    size = {im["id"]: (im["height"], im["width"]) for im in doc["images"]}
    assert doc["annotations"]
    for a in doc["annotations"]:
        m = mu.decode(a["segmentation"]).astype(bool)
        assert m.shape == size[a["image_id"]] and m.any()
        ys, xs = np.nonzero(m)
        x, y, w, h = a["bbox"]
        assert np.allclose((x, y, x + w, y + h), (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)), a["id"]
        assert a["area"] == pytest.approx(m.sum(), abs=1)
        if "segmentation_amodal" in a:
            assert not (m & ~mu.decode(a["segmentation_amodal"]).astype(bool)).any(), a["id"]
        if "keypoints" in a:
            kp = np.array(a["keypoints"], float).reshape(-1, 3)
            vis = kp[kp[:, 2] == 2]
            H, W = size[a["image_id"]]
            assert ((vis[:, 0] >= -0.5) & (vis[:, 0] <= W - 0.5) & (vis[:, 1] >= -0.5) & (vis[:, 1] <= H - 0.5)).all()


def test_coco17_points_sit_on_the_rider():
    """Hand-checkable anatomy of the regressor on the rest T-pose: face above shoulders above hips
    above knees above ankles, left on -Z, wrists farther out than elbows, the nose in front."""
    import torch
    from splatting.dataset.person_keypoints import COCO17, PersonKeypoints
    from splatting.rider.roster import load_rider
    r = load_rider(RIDER)
    pk = PersonKeypoints(r)
    P = pk.posed(torch.eye(3, dtype=torch.float64).expand(1, 24, 3, 3), torch.zeros(1, 3))[0].numpy()
    p = dict(zip(COCO17, P))
    assert p["nose"][0] > p["left_eye"][0] > p["left_ear"][0]
    assert p["nose"][1] > p["left_shoulder"][1] > p["left_hip"][1] > p["left_knee"][1] > p["left_ankle"][1] > 0
    for n in ("eye", "ear", "shoulder", "elbow", "wrist", "hip", "knee", "ankle"):
        assert p[f"left_{n}"][2] < 0 < p[f"right_{n}"][2], n
    assert abs(p["left_wrist"][2]) > abs(p["left_elbow"][2]) > abs(p["left_shoulder"][2])
    J = r.joints.numpy()
    assert abs(p["left_hip"][2]) > abs(J[1, 2])  # COCO hips lie lateral of the SMPL hip joints
    assert np.linalg.norm(p["left_knee"] - J[4]) < 0.03  # limb centre at the knee

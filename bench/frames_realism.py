"""Do off-the-shelf models see the inserted riders as people?  BlazePose (mediapipe 0.10.21,
`mp.solutions.pose`, default complexity, weights inside the package) on the inserted riders of a
frames-mode dataset and on the real pedestrians and cyclists of its KITTI frames.

Per person box at least --min-px tall (inserted: the `rider` annotations' visible boxes, of cyclists
whose whole (rider + bike) visibility is >= 0.9 and truncation < 0.1; real: the frame's Pedestrian/Cyclist rows with occluded 0 and truncated < 0.1): a crop around the box (25 % margin,
the box centred), scaled to 256 px high, then BlazePose in static-image mode.
- detected share: the crops in which it finds a person;
- PCK@0.2 (inserted only: the real rows have no keypoints): the share of our visible (v = 2) COCO-17
  labels within 0.2 torso sizes (the distance between the shoulders' and the hips' midpoints, from
  our labels) of BlazePose's point for the same joint, over the detected crops.
Runs in its own virtual environment (mediapipe wants numpy < 2; it stays out of the main
requirements); reads only JSON, PNG and label text, so it needs no torch:

    python3 -m venv VENV && VENV/bin/pip install mediapipe==0.10.21 "numpy<2" pillow
    VENV/bin/python bench/frames_realism.py DATASET --frames ../shared/realism/kitti_dev
"""
import argparse
import json
import os

import numpy as np
from PIL import Image

# BlazePose landmark index of each COCO-17 keypoint (nose, eyes, ears, shoulders, elbows, wrists, hips,
# knees, ankles)
COCO_FROM_BLAZE = (0, 2, 5, 7, 8, 11, 12, 13, 14, 15, 16, 23, 24, 25, 26, 27, 28)
CROP_H = 256


def crop(img, box, margin=0.25):
    """(crop uint8, (x0, y0, scale)): the box (x, y, w, h) grown by margin, scaled to CROP_H high."""
    x, y, w, h = box
    side_h, side_w = h * (1 + 2 * margin), max(w * (1 + 2 * margin), h * 0.6)
    cx, cy = x + w / 2, y + h / 2
    x0, y0 = int(round(cx - side_w / 2)), int(round(cy - side_h / 2))
    x1, y1 = int(round(cx + side_w / 2)), int(round(cy + side_h / 2))
    H, W = img.shape[:2]
    pad = np.zeros((y1 - y0, x1 - x0, 3), np.uint8)
    sx0, sy0, sx1, sy1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
    pad[sy0 - y0:sy1 - y0, sx0 - x0:sx1 - x0] = img[sy0:sy1, sx0:sx1]
    s = CROP_H / pad.shape[0]
    out = np.asarray(Image.fromarray(pad).resize((max(1, int(round(pad.shape[1] * s))), CROP_H), Image.BILINEAR))
    return out, (x0, y0, s)


def pose_points(pose, img):
    """BlazePose on an RGB uint8 crop -> (33, 2) pixel coordinates in the crop, or None."""
    r = pose.process(img)
    if r.pose_landmarks is None:
        return None
    h, w = img.shape[:2]
    return np.array([[p.x * w, p.y * h] for p in r.pose_landmarks.landmark])


def pck(pred, kps, frame, thr=0.2):
    """(hits, counted) of our visible COCO-17 points against BlazePose's (crop pixels -> image)."""
    x0, y0, s = frame
    k = np.asarray(kps, float).reshape(17, 3)
    p = pred[list(COCO_FROM_BLAZE)] / s + [x0, y0]
    if not (k[[5, 6, 11, 12], 2] > 0).all():
        return 0, 0
    torso = np.linalg.norm(k[[5, 6], :2].mean(0) - k[[11, 12], :2].mean(0))
    vis = k[:, 2] == 2
    d = np.linalg.norm(p - k[:, :2], axis=1)
    return int((d[vis] <= thr * torso).sum()), int(vis.sum())


def read_rows(path):
    rows = []
    with open(path) as f:
        for line in f:
            p = line.split()
            if len(p) >= 15:
                rows.append({"type": p[0], "truncated": float(p[1]), "occluded": int(float(p[2])),
                             "box": [float(x) for x in p[4:8]]})
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset")
    ap.add_argument("--frames", required=True, help="the KITTI folder the dataset was made from")
    ap.add_argument("--min-px", type=float, default=64)
    a = ap.parse_args(argv)
    for p in (os.path.join(a.dataset, "annotations.json"), os.path.join(a.frames, "image_2")):
        if not os.path.exists(p):
            raise SystemExit(f"frames_realism: error: no {p}")
    try:
        import mediapipe as mp  # here, not at the top: it lives in its own venv (numpy < 2), not the project's
    except ImportError:
        raise SystemExit("frames_realism: error: needs mediapipe==0.10.21 (its own venv; see the module's docstring)")
    with open(os.path.join(a.dataset, "annotations.json")) as f:
        doc = json.load(f)
    rider = next(c["id"] for c in doc["categories"] if c.get("key") == "rider")
    cid = next(c["id"] for c in doc["categories"] if c.get("key") == "cyclist")
    cyc = {(an["image_id"], an["instance"]): an for an in doc["annotations"] if an["category_id"] == cid}
    res = {"inserted": {"n": 0, "detected": 0, "pck_hits": 0, "pck_points": 0, "heights": []},
           "real": {"n": 0, "detected": 0, "heights": []}}
    with mp.solutions.pose.Pose(static_image_mode=True) as pose:
        for im in doc["images"]:
            img = np.asarray(Image.open(os.path.join(a.dataset, "images", im["file_name"])).convert("RGB"))
            for an in doc["annotations"]:
                if an["image_id"] != im["id"] or an["category_id"] != rider or an["bbox"][3] < a.min_px:
                    continue
                whole = cyc.get((im["id"], an["instance"]))  # the whole cyclist, unoccluded, as the real rows
                if whole is None or whole["visibility"] < 0.9 or whole["truncation"] >= 0.1:
                    continue
                c, fr = crop(img, an["bbox"])
                p = pose_points(pose, c)
                r = res["inserted"]
                r["n"] += 1
                r["heights"].append(an["bbox"][3])
                if p is not None:
                    r["detected"] += 1
                    hit, cnt = pck(p, an["keypoints"], fr)
                    r["pck_hits"] += hit
                    r["pck_points"] += cnt
        for fid in sorted(f[:-4] for f in os.listdir(os.path.join(a.frames, "image_2")) if f.endswith(".png")):
            img = np.asarray(Image.open(os.path.join(a.frames, "image_2", fid + ".png")).convert("RGB"))
            for r_ in read_rows(os.path.join(a.frames, "label_2", fid + ".txt")):
                x1, y1, x2, y2 = r_["box"]
                if r_["type"] not in ("Pedestrian", "Cyclist") or r_["occluded"] != 0 or r_["truncated"] >= 0.1 \
                        or y2 - y1 < a.min_px:
                    continue
                c, _ = crop(img, [x1, y1, x2 - x1, y2 - y1])
                r = res["real"]
                r["n"] += 1
                r["heights"].append(y2 - y1)
                r["detected"] += int(pose_points(pose, c) is not None)
    out = {}
    for k, r in res.items():
        o = {"n": r["n"], "detected_share": round(r["detected"] / r["n"], 3) if r["n"] else None,
             "height_px_median": round(float(np.median(r["heights"])), 1) if r["heights"] else None}
        if "pck_points" in r:
            o["pck_0.2_torso"] = round(r["pck_hits"] / r["pck_points"], 3) if r["pck_points"] else None
            o["pck_points"] = r["pck_points"]
        out[k] = o
    out["min_px"] = a.min_px
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()

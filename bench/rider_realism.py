"""Do the roster riders look like people to an off-the-shelf pose model?  BlazePose (mediapipe 0.10.21,
`mp.solutions.pose`, default model complexity, weights inside the package) on every roster rider riding a
bike, rendered the dataset's way, at 64, 128 and 256 px person (rider box) height.

Renders (the project's venv, torch): each anny roster rider as the dataset draws it (splatting.dataset's
Assets: its trained avatar under --riders-root when one exists, else the mesh avatar, on the stand-in
city bike, IK-posed by the cyclist), at VIEWS (two crank angles x side-on both ways and two
three-quarter views; --views N adds more crank angles and yaws), through the nuScenes camera 5 m away with its intrinsics scaled so that the rider's
visible box is H px high, over a flat grey; COCO-17 labels from the rider's own mesh keypoints
(splatting.dataset.person_keypoints), visibility by the dataset's depth test.  Then BlazePose
(bench/frames_realism.py's crop: the rider box + 25 %, scaled to 256 px high; static-image mode) in
mediapipe's own venv (it wants numpy < 2 and no torch), a subprocess of this file (--pose-worker).

Per height: detected share (crops in which BlazePose finds a person); PCK@0.2 of the torso (our
shoulder-midpoint to hip-midpoint distance) over the detected crops, on all 17 COCO points (BlazePose
predicts every one; pck_visible: on our v = 2 points alone), pooled, and the median over riders of
each rider's PCK.  Key: rider_realism = {"64": {...}, "128": ..., "256": ...}.

The BlazePose venv: BLAZEPOSE_PYTHON (or --pose-python), e.g.
    python3 -m venv VENV && VENV/bin/pip install mediapipe==0.10.21 "numpy<2" pillow
Results are cached under OUT/rider_realism/ keyed by the roster file, the rider/cyclist/dataset code,
this file and the settings; a matching key is read back (provenance "reused").
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np
from PIL import Image

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench import bench_parser  # noqa: E402
from bench.frames_realism import COCO_FROM_BLAZE, crop, pose_points  # noqa: E402  (numpy + PIL only)

HEIGHTS = (64, 128, 256)
# (theta_p_deg, yaw_deg): side-on riding image-right and image-left, then three-quarter front and back
VIEWS = ((60.0, 180.0), (240.0, 0.0), (150.0, 135.0), (330.0, 315.0))


def views(n=len(VIEWS)):
    """The first n views: VIEWS, then crank angles in 97-degree steps and yaws in golden-angle steps."""
    extra = [(float(97 * k % 360), round(137.508 * k % 360, 3)) for k in range(len(VIEWS), n)]
    return (tuple(VIEWS) + tuple(extra))[:n]
DISTANCE_M = 5.0
BACKGROUND = 0.5
PCK_THR = 0.2
CODE = ("splatting/rider", "splatting/cyclist", "splatting/dataset", "splatting/raster", "blend_assets/riders.yaml",
        "bench/rider_realism.py", "bench/frames_realism.py")


# ------------------------------------------------------------------ rendering (project venv)

def _camera(scale):
    from splatting.dataset import camera_presets
    from splatting.dataset.config_models import Camera
    spec = camera_presets.resolve(Camera(preset="nuscenes", pitch_deg=0.0, roll_deg=0.0, scale=float(scale)))
    return camera_presets.street_camera(spec)


def _render(assets, bike, rider, theta_p, yaw, scale):
    """(rgb (H, W, 3) uint8 over grey, rider box (x, y, w, h) or None, COCO-17 (17, 3) [u, v, vis])."""
    import torch

    from cyclist_formats.instances import RIDER_ID
    from splatting.cyclist.render import keypoint_visibility, over, project_points
    from splatting.cyclist.scene_render import render_scene
    from splatting.dataset.person_keypoints import COCO17_TOLERANCE_M

    cyc = assets.cyclist(bike, rider)
    pose = torch.tensor([theta_p, 0.0, 0.0, yaw, 0.0, 0.0, 0.0, DISTANCE_M], dtype=torch.float64)
    frame = cyc.pose(pose)[0]
    cam = _camera(scale)
    slots = torch.where(frame.ids == RIDER_ID, 2, 1).long()
    L = render_scene(frame.gaussians, slots, 3, cam)
    rgb = over({"rgb": L["rgb"], "alpha": L["alpha"]}, np.full(L["rgb"].shape, BACKGROUND, np.float32))
    ys, xs = np.nonzero(L["label"] == 2)
    box = None if len(xs) == 0 else (float(xs.min()), float(ys.min()), float(xs.max() - xs.min() + 1),
                                     float(ys.max() - ys.min() + 1))
    rot, root = assets.avatars[rider].last
    pts = assets.persons[rider].posed(rot, root)[0].numpy()
    uv, z = project_points(pts, cam)
    px = 1.0 / float(cam.K[0, 0])
    vis = keypoint_visibility(uv, z, L["alpha"], L["depth"], np.asarray(COCO17_TOLERANCE_M) + z * px)
    return rgb, box, np.column_stack([uv, vis])


def render_crops(out_dir, riders, riders_root, n_views=len(VIEWS), log=print):
    """Write the crops (PNG) and labels.json for every rider x view x height into out_dir."""
    import torch

    from splatting import paths
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets
    from splatting.dataset.looks_sheet import STAND_IN_BIKE

    torch.set_num_threads(1)
    scratch = tempfile.mkdtemp(prefix="rider_realism_")
    try:
        shutil.copytree(os.path.join(paths.BLEND_ASSETS, "stand_in_bike", STAND_IN_BIKE),
                        os.path.join(scratch, STAND_IN_BIKE))
        cfg = resolve_assets(validate({"mode": "street", "camera": {"preset": "nuscenes"}, "seed": 0,
                                       "bikes": [STAND_IN_BIKE], "bikes_root": scratch, "riders": list(riders),
                                       "riders_root": riders_root}))
        assets = Assets(cfg)
        rows = []
        for ri, rider in enumerate(riders):
            for vi, (tp, yaw) in enumerate(views(n_views)):
                _, box0, _ = _render(assets, STAND_IN_BIKE, rider, tp, yaw, 1.0)
                for h in HEIGHTS:
                    s = h / box0[3]
                    rgb, box, kp = _render(assets, STAND_IN_BIKE, rider, tp, yaw, s)
                    if box is None:
                        continue
                    c, (x0, y0, sc) = crop(rgb, box)
                    name = f"{rider}_{vi}_{h}.png"
                    Image.fromarray(c).save(os.path.join(out_dir, name))
                    k = kp.copy()
                    k[:, 0] = (k[:, 0] - x0) * sc  # labels in crop pixels
                    k[:, 1] = (k[:, 1] - y0) * sc
                    rows.append({"file": name, "rider": rider, "view": vi, "height": h, "box_h": box[3],
                                 "keypoints": k.round(3).tolist()})
            log(f"rider_realism: rendered {ri + 1}/{len(riders)} riders")
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    with open(os.path.join(out_dir, "labels.json"), "w") as f:
        json.dump(rows, f)
    return rows


# ------------------------------------------------------------------ BlazePose (mediapipe venv)

def pose_worker(folder):
    """Run BlazePose on every labels.json crop of folder -> poses.json {file: (33, 2) points or None}."""
    import mediapipe as mp  # here: only mediapipe's own venv has it
    with open(os.path.join(folder, "labels.json")) as f:
        rows = json.load(f)
    out = {}
    with mp.solutions.pose.Pose(static_image_mode=True) as pose:
        for r in rows:
            img = np.asarray(Image.open(os.path.join(folder, r["file"])).convert("RGB"))
            p = pose_points(pose, img)
            out[r["file"]] = None if p is None else p.round(3).tolist()
    with open(os.path.join(folder, "poses.json.tmp"), "w") as f:
        json.dump({"mediapipe": mp.__version__, "poses": out}, f)
    os.replace(os.path.join(folder, "poses.json.tmp"), os.path.join(folder, "poses.json"))


# ------------------------------------------------------------------ scoring

def crop_pck(pred, kps, thr=PCK_THR, visible_only=False):
    """(hits, counted) of our labelled COCO-17 points within thr torso sizes of BlazePose's (crop pixels)."""
    k = np.asarray(kps, float).reshape(17, 3)
    if not (k[[5, 6, 11, 12], 2] > 0).all():
        return 0, 0
    torso = np.linalg.norm(k[[5, 6], :2].mean(0) - k[[11, 12], :2].mean(0))
    use = k[:, 2] == 2 if visible_only else k[:, 2] > 0
    d = np.linalg.norm(np.asarray(pred, float)[list(COCO_FROM_BLAZE)] - k[:, :2], axis=1)
    return int((d[use] <= thr * torso).sum()), int(use.sum())


def score(rows, poses):
    """{height: {n, detected_share, pck_0.2_torso, pck_0.2_torso_visible, pck_rider_median, box_h_median}}."""
    out = {}
    for h in HEIGHTS:
        sel = [r for r in rows if r["height"] == h]
        det = [r for r in sel if poses.get(r["file"]) is not None]
        hits = [crop_pck(poses[r["file"]], r["keypoints"]) for r in det]
        hv = [crop_pck(poses[r["file"]], r["keypoints"], visible_only=True) for r in det]
        per_rider = {}
        for r, (a, b) in zip(det, hits):
            per_rider.setdefault(r["rider"], [0, 0])
            per_rider[r["rider"]][0] += a
            per_rider[r["rider"]][1] += b
        ratio = lambda xs: round(sum(a for a, _ in xs) / max(1, sum(b for _, b in xs)), 3) if xs else None
        out[str(h)] = {"n": len(sel), "detected_share": round(len(det) / len(sel), 3) if sel else None,
                       "pck_0.2_torso": ratio(hits), "pck_0.2_torso_visible": ratio(hv),
                       "pck_rider_median": round(float(np.median([a / b for a, b in per_rider.values() if b])), 3)
                       if per_rider else None,
                       "box_h_median": round(float(np.median([r["box_h"] for r in sel])), 1) if sel else None}
    return out


# ------------------------------------------------------------------ the stage

def blazepose_python(explicit=None):
    return explicit or os.environ.get("BLAZEPOSE_PYTHON")


def cache_key(riders, riders_root, n_views=len(VIEWS)):
    from bench.provenance import code_version, tree_hash
    avatars = {r: tree_hash(os.path.join(riders_root, r), (".ply", ".npz")) for r in riders}
    return {"riders": list(riders), "avatars": avatars, "heights": list(HEIGHTS), "views": [list(v) for v in views(n_views)],
            "distance_m": DISTANCE_M, "code": code_version(*CODE)}


def measure(out_dir, python, riders=None, riders_root=None, n_views=len(VIEWS), log=print):
    """The realism numbers (cached under out_dir/rider_realism); returns (result, reused)."""
    from bench.provenance import key_matches, write_key
    from splatting.rider.roster import load_roster
    riders = riders or [r["id"] for r in load_roster() if r.get("body", "anny") == "anny"]
    riders_root = riders_root or os.path.join(out_dir, "rider_realism", "no_avatars")
    folder = os.path.join(out_dir, "rider_realism")
    key, key_path, res_path = cache_key(riders, riders_root, n_views), os.path.join(folder, "key.json"), os.path.join(folder, "result.json")
    if key_matches(key_path, key) and os.path.isfile(res_path):
        with open(res_path) as f:
            return json.load(f), True
    crops = os.path.join(folder, "crops")
    shutil.rmtree(crops, ignore_errors=True)
    os.makedirs(crops)
    rows = render_crops(crops, riders, riders_root, n_views, log=log)
    r = subprocess.run([python, os.path.abspath(__file__), "--pose-worker", crops], capture_output=True, text=True)
    if r.returncode != 0 or not os.path.isfile(os.path.join(crops, "poses.json")):
        tail = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["no output"]
        raise RuntimeError(f"BlazePose worker failed (exit {r.returncode}): {tail[0]}")
    with open(os.path.join(crops, "poses.json")) as f:
        pj = json.load(f)
    result = {"mediapipe": pj["mediapipe"], "riders": len(riders), "views": n_views, **score(rows, pj["poses"])}
    from cyclist_formats.atomic import write_json
    write_json(res_path, result)
    write_key(key_path, key)
    return result, False


def run(results, out_dir, python=None, riders=None, riders_root=None, n_views=len(VIEWS)):
    from bench.provenance import not_measured, record
    py = blazepose_python(python)
    if not py or not os.path.isfile(py):
        not_measured(results, "rider_realism", "needs mediapipe==0.10.21 in its own venv: set BLAZEPOSE_PYTHON "
                                               "(bench/rider_realism.py's docstring)")
        return
    res, reused = measure(out_dir, py, riders, riders_root, n_views)
    results["rider_realism"] = res
    record(results, "rider_realism", "reused" if reused else "fresh", blazepose=py,
           avatars=riders_root or "mesh avatars (no trained ones)")


def main(argv=None):
    ap = bench_parser("rider_realism", __doc__)
    ap.add_argument("--pose-python", help="the python of mediapipe's venv (default: $BLAZEPOSE_PYTHON)")
    ap.add_argument("--riders", help="comma list of rider ids (default: the anny roster)")
    ap.add_argument("--riders-root", help="trained avatars (ID/rider.ply, skinning.npz); default: mesh avatars")
    ap.add_argument("--views", type=int, default=len(VIEWS), help=f"views per rider (default {len(VIEWS)}; more: views())")
    ap.add_argument("--pose-worker", help=argparse_hidden())
    a = ap.parse_args(argv)
    if a.pose_worker:
        if not os.path.isfile(os.path.join(a.pose_worker, "labels.json")):
            ap.error(f"no labels.json in {a.pose_worker}")
        pose_worker(a.pose_worker)
        return 0
    py = blazepose_python(a.pose_python)
    if not py or not os.path.isfile(py):
        ap.error("needs the python of a venv with mediapipe==0.10.21: --pose-python or BLAZEPOSE_PYTHON")
    if not 1 <= a.views <= 360:
        ap.error(f"--views must be 1..360, got {a.views}")
    if a.riders_root and not os.path.isdir(a.riders_root):
        ap.error(f"no folder {a.riders_root}")
    riders = [x.strip() for x in a.riders.split(",") if x.strip()] if a.riders else None
    if riders:
        from cyclist_formats.errors import UserError
        from splatting.rider.roster import get_spec
        try:
            for r in riders:
                get_spec(r)
        except UserError as e:
            ap.error(str(e))
    results = {}
    run(results, a.out, py, riders, a.riders_root, a.views)
    print(json.dumps(results, indent=1))
    return 0


def argparse_hidden():
    import argparse
    return argparse.SUPPRESS


if __name__ == "__main__":
    raise SystemExit(main())

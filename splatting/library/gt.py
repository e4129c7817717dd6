"""A bike's ground-truth check: its composed part Gaussians against the Blender render of the
articulated mesh at a few fixed random poses (same pose ranges as bench/bike_gt.py).

Blender renders with blender_scripts/render_pose.py (a subprocess per pose, camera = a ring
camera of views/whole/cameras.json, so at the library's view size); the Gaussians render with the
project's rasterizer from the same camera.  Numbers: mask IoU (alpha > 0.5) and box PSNR (RGB on
black over the union box of both masks, where the bike is: a whole-image PSNR is dominated by the
empty background).
"""
import os
import subprocess
import sys

from PIL import Image
import numpy as np
import torch

from cyclist_formats.atomic import atomic_path
from splatting.bike.model import BikeModel
from splatting.bike.pose import sample_poses
from splatting.raster.camera import load_cameras
from splatting.raster.api import render_gaussians
from splatting.training.metrics import box_psnr, mask_iou

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def render_blender(bike_dir, pose, cam_index, out_png, samples=None):
    cams = os.path.join(bike_dir, "views", "whole", "cameras.json")
    cmd = [sys.executable, os.path.join(ROOT, "blender_scripts", "render_pose.py"), "--bike", bike_dir,
           "--pose", ",".join(f"{v:.6f}" for v in pose), "--camera", f"{cams}:camera{int(cam_index):04d}",
           "--out", out_png, "--threads", "1"]  # the gt task declares one CPU; Cycles' pixels do not depend on it
    if samples:
        cmd += ["--samples", str(samples)]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"Blender ground truth of {bike_dir} failed (exit {r.returncode}): "
                           + " | ".join(r.stdout.strip().splitlines()[-3:]))


def ground_truth(bike_dir, out_dir, n_poses=3, samples=None, seed=0):
    """-> (metrics, [files written]).  Renders skipped when their PNG exists (resumable)."""

    torch.set_num_threads(1)
    poses, cams = sample_poses(n_poses, seed)
    os.makedirs(out_dir, exist_ok=True)
    model = BikeModel.load(bike_dir)
    ring, _ = load_cameras(os.path.join(bike_dir, "views", "whole", "cameras.json"))
    rows, files = [], []
    for i, (pose, cam) in enumerate(zip(poses, cams)):
        gt_png = os.path.join(out_dir, f"gt_{i:03d}.png")
        if not os.path.isfile(gt_png):
            render_blender(bike_dir, pose, cam, gt_png, samples)
        gt = np.asarray(Image.open(gt_png).convert("RGBA")).astype(np.float64) / 255
        with torch.no_grad():
            out = render_gaussians(model.pose(torch.tensor(pose, dtype=torch.float64)).gaussians, ring[int(cam)],
                                   antialiased=model.antialiased, eps2d=model.eps2d)
        rgb, alpha = out["rgb"].clamp(0, 1).double().numpy(), out["alpha"].double().numpy()
        gt_rgb, m_gt, m = gt[..., :3] * gt[..., 3:4], gt[..., 3] > 0.5, alpha > 0.5
        rows.append({"pose": [round(float(v), 3) for v in pose], "camera": int(cam),
                     "iou": round(mask_iou(m, m_gt), 4), "box_psnr": round(box_psnr(rgb, gt_rgb, m, m_gt), 3)})
        splat_png = os.path.join(out_dir, f"splat_{i:03d}.png")
        straight = np.where(alpha[..., None] > 1e-6, rgb / np.maximum(alpha[..., None], 1e-6), 0.0).clip(0, 1)
        with atomic_path(splat_png) as tmp:  # straight alpha, like the Blender RGBA beside it
            rgba = np.concatenate([straight, alpha[..., None].clip(0, 1)], -1)
            Image.fromarray((rgba * 255).round().astype(np.uint8)).save(tmp, format="PNG")
        files += [gt_png, splat_png]
    iou = np.array([r["iou"] for r in rows])
    ps = np.array([r["box_psnr"] for r in rows])
    metrics = {"gt_poses": len(rows), "gt_iou": round(float(iou.mean()), 4), "gt_iou_min": round(float(iou.min()), 4),
               "gt_box_psnr": round(float(np.nanmean(ps)), 3), "gt_box_psnr_min": round(float(np.nanmin(ps)), 3),
               "rows": rows}
    return metrics, files

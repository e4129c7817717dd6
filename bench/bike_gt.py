"""Gaussian-space bike vs Blender at the same 8-DoF pose (issue 4's ground truth).

For random poses (θs in ±60°, θp over the full circle, yaw over the full circle, roll and
pitch in ±15°, translations that keep the bike in view) and random ring cameras, render the
composed part Gaussians with the project's rasterizer and the articulated mesh with Blender
(blender_scripts/render_pose.py's core, lights following the bike), then compare mask IoU
(alpha > 0.5), PSNR (RGB on black, whole 512² image), box PSNR (the union of both masks' box + 8 px,
as blender_compare) and the posed keypoints. The Gaussians are drawn antialiased when their parts were
trained so (BikeModel.antialiased), with the low-pass they were trained with (BikeModel.eps2d).
Key: bike_gt = {poses, iou_mean, psnr_mean, iou_min, psnr_min, box_psnr_mean, box_psnr_min}; table and worst-case picture
beside results.json.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

from splatting.bike.pose import sample_poses  # noqa: F401  (bench modules import it from here too)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


POSES = 20  # the ground-truth check's random poses (seed 0); bike_relit scores the same ones


def blender_worker(bike_dir, poses_json, out_dir, samples):
    """Runs under bpy: one render + posed keypoints per pose."""
    sys.path.insert(0, ROOT)
    from dataclasses import replace

    from addon.core.render import render
    from addon.core.render.render_pose import render_pose

    with open(poses_json) as f:
        job = json.load(f)
    s = replace(render.RenderSettings(), samples=samples)
    for i, (pose, cam) in enumerate(zip(job["poses"], job["cameras"])):
        out = os.path.join(out_dir, f"gt_{i:03d}.png")
        if os.path.isfile(out) and os.path.isfile(out[:-4] + "_kp.json"):
            continue
        render_pose(bike_dir, pose, f"{os.path.join(bike_dir, 'views', 'whole', 'cameras.json')}:camera{cam:04d}",
                    out, out[:-4] + "_kp.json", s)
        print(f"  blender pose {i + 1}/{len(job['poses'])}", flush=True)


def find_bike(bikes_dir):
    for b in sorted(os.listdir(bikes_dir)) if os.path.isdir(bikes_dir) else []:
        d = os.path.join(bikes_dir, b)
        g = os.path.join(d, "gaussians")
        if os.path.isfile(os.path.join(g, "frame.ply")) and os.path.isfile(os.path.join(g, "steering.ply")):
            return d
    return None


def compare(bike_dir, poses, cams, gt_dir):
    import torch

    from bench.compare import load_rgba, mask_iou, psnr, union_box
    from splatting.bike.model import BikeModel
    from splatting.raster.camera import load_cameras
    from splatting.raster.api import render_gaussians

    model = BikeModel.load(bike_dir)
    ring, _ = load_cameras(os.path.join(bike_dir, "views", "whole", "cameras.json"))
    rows, renders = [], []
    with torch.no_grad():
        for i, (pose, cam) in enumerate(zip(poses, cams)):
            posed = model.pose(torch.tensor(pose, dtype=torch.float64))
            out = render_gaussians(posed.gaussians, ring[int(cam)], antialiased=model.antialiased, eps2d=model.eps2d)
            rgb = out["rgb"].clamp(0, 1).numpy()
            alpha = out["alpha"].numpy()
            gt_rgb, m_gt = load_rgba(os.path.join(gt_dir, f"gt_{i:03d}.png"))
            m = alpha > 0.5
            with open(os.path.join(gt_dir, f"gt_{i:03d}_kp.json")) as f:
                kp_gt = json.load(f)["keypoints"]
            kp_err = max(float(np.linalg.norm(posed.keypoints[k].numpy() - np.asarray(kp_gt[k]))) for k in kp_gt)
            x0, y0, x1, y1 = union_box(m, m_gt, pad=8)
            rows.append({"pose": [round(float(v), 3) for v in pose], "camera": int(cam), "iou": mask_iou(m, m_gt),
                         "psnr": psnr(rgb, gt_rgb), "box_psnr": psnr(rgb[y0:y1, x0:x1], gt_rgb[y0:y1, x0:x1]),
                         "kp_err_mm": kp_err * 1000})
            renders.append((gt_rgb, rgb))
    return rows, renders


def run(results, out_dir, n_poses=POSES, seed=0, samples=16):
    from bench.compare import renders_for, side_by_side, write_table
    from bench.provenance import RENDER_CODE, bike_assets, code_version, file_hash, not_measured, record

    bike_dir = find_bike(os.path.join(out_dir, "bikes"))
    if bike_dir is None:
        why = f"no bike with trained part Gaussians under {os.path.join(out_dir, 'bikes')}"
        print(f"  bike_gt: {why} - skipped")
        not_measured(results, "bike_gt", why)
        return None
    poses, cams = sample_poses(n_poses, seed)
    cams_json = os.path.join(bike_dir, "views", "whole", "cameras.json")
    # the renders are reused only for this bike's files, poses, cameras, samples and render code
    key = {**bike_assets(bike_dir), "cameras.json": file_hash(cams_json), "poses": poses.tolist(),
           "cameras": cams.tolist(), "samples": samples, "code": code_version(*RENDER_CODE)}
    gt_dir = renders_for(os.path.join(out_dir, "bike_gt"), key)
    reused = all(os.path.isfile(os.path.join(gt_dir, f"gt_{i:03d}{x}")) for i in range(len(poses)) for x in (".png", "_kp.json"))
    job = os.path.join(gt_dir, "poses.json")
    with open(job, "w") as f:
        json.dump({"poses": poses.tolist(), "cameras": cams.tolist()}, f)
    subprocess.run([sys.executable, __file__, "--worker", bike_dir, job, gt_dir, str(samples)], check=True)
    rows, renders = compare(bike_dir, poses, cams, gt_dir)
    iou, ps = np.array([r["iou"] for r in rows]), np.array([r["psnr"] for r in rows])
    box = np.array([r["box_psnr"] for r in rows])
    worst = int(np.argmin(ps))

    side_by_side(*renders[worst], os.path.join(out_dir, "bike_gt_worst.png"))
    results["bike_gt"] = {"poses": len(rows), "iou_mean": float(iou.mean()), "psnr_mean": float(ps.mean()),
                          "iou_min": float(iou.min()), "psnr_min": float(ps.min()),
                          "box_psnr_mean": float(box.mean()), "box_psnr_min": float(box.min()),
                          "kp_err_max_mm": float(max(r["kp_err_mm"] for r in rows))}
    # the Gaussians are drawn now; only Blender's references may come from an earlier run
    record(results, "bike_gt", "fresh", bike=os.path.abspath(bike_dir),
           blender_renders="reused (same key)" if reused else "rendered")
    lines = ["| # | pose p,s,X,Y,Z,tx,ty,tz | camera | IoU | PSNR dB | box PSNR dB | keypoint err mm |",
             "|---|---|---|---|---|---|---|"]
    for i, r in enumerate(rows):
        lines.append(f"| {i} | {', '.join(f'{v:.1f}' for v in r['pose'][:5])}, {', '.join(f'{v:.2f}' for v in r['pose'][5:])} "
                     f"| {r['camera']} | {r['iou']:.4f} | {r['psnr']:.2f} | {r['box_psnr']:.2f} | {r['kp_err_mm']:.4f} |")
    lines.append(f"\nWorst case: pose {worst} (GT | Gaussians | 4x |diff|) in bike_gt_worst.png; bike {os.path.basename(bike_dir)}.")
    write_table(out_dir, "bike_gt_table.md", lines)
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="bike ground-truth comparison (worker runs under bpy)")
    ap.add_argument("--worker", nargs=4, metavar=("BIKE", "POSES_JSON", "OUT_DIR", "SAMPLES"))
    ap.add_argument("--out", help="bench output folder holding bikes/ (standalone run)")
    a = ap.parse_args()
    if a.worker:
        blender_worker(a.worker[0], a.worker[1], a.worker[2], int(a.worker[3]))
    else:
        sys.path.insert(0, ROOT)
        res = {}
        run(res, a.out)
        print(json.dumps(res, indent=1))

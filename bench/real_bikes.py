"""Curated real bikes through the ground-truth check: part Gaussians vs Blender at random poses.

For each bike folder given (curated with blender_scripts/curate.py, views rendered, part
Gaussians trained), render the articulated mesh in Blender (bench/bike_gt.py's worker) and the
composed Gaussians with the project's rasterizer at the same random 8-DoF poses and ring
cameras; report mask IoU (alpha > 0.5) and box PSNR (RGB on black, inside the box around both
masks), and write a picture: per bike, Blender | Gaussians at the random pose where the bike
covers most of the image, cropped to the box around both masks.

    .venv/bin/python bench/real_bikes.py --bikes out/real/bikes/lanejustice [...] --poses 6 --image docs/img/real_bikes.png
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def check_bike(bike_dir, n_poses, seed, samples):
    import torch

    from bench.bike_gt import sample_poses
    from bench.compare import load_rgba, mask_iou
    from splatting.training.metrics import box_psnr, union_box
    from splatting.bike.model import BikeModel
    from splatting.raster.camera import load_cameras
    from splatting.raster.api import render_gaussians

    poses, cams = sample_poses(n_poses, seed)
    gt_dir = os.path.join(bike_dir, "gt_check")
    os.makedirs(gt_dir, exist_ok=True)
    job = os.path.join(gt_dir, "poses.json")
    from bench.provenance import RENDER_CODE, bike_assets, code_version
    # renders kept only for the same poses, samples, bike files and render code
    doc = {"poses": poses.tolist(), "cameras": cams.tolist(), "samples": samples, "assets": bike_assets(bike_dir),
           "code": code_version(*RENDER_CODE)}
    old = None
    if os.path.isfile(job):
        with open(job) as f:
            old = json.load(f)
    if old != doc:   # the worker keeps finished renders by index: drop those of other poses
        for name in os.listdir(gt_dir):
            if name.startswith("gt_"):
                os.remove(os.path.join(gt_dir, name))
    with open(job, "w") as f:
        json.dump(doc, f)
    subprocess.run([sys.executable, os.path.join(ROOT, "bench", "bike_gt.py"), "--worker", bike_dir, job, gt_dir,
                    str(samples)], check=True)
    model = BikeModel.load(bike_dir)
    ring, _ = load_cameras(os.path.join(bike_dir, "views", "whole", "cameras.json"))
    rows, best = [], None
    with torch.no_grad():
        for i, (pose, cam) in enumerate(zip(poses, cams)):
            out = render_gaussians(model.pose(torch.tensor(pose, dtype=torch.float64)).gaussians, ring[int(cam)],
                                   antialiased=model.antialiased, eps2d=model.eps2d)  # drawn as trained
            rgb, alpha = out["rgb"].clamp(0, 1).numpy(), out["alpha"].numpy()
            gt_rgb, m_gt = load_rgba(os.path.join(gt_dir, f"gt_{i:03d}.png"))
            m = alpha > 0.5
            rows.append({"iou": mask_iou(m, m_gt), "box_psnr": box_psnr(rgb, gt_rgb, m, m_gt)})
            if best is None or m_gt.sum() > best[0]:
                x0, y0, x1, y1 = union_box(m, m_gt, pad=6)
                best = (m_gt.sum(), gt_rgb[y0:y1, x0:x1], rgb[y0:y1, x0:x1])
    return rows, best[1:]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bikes", nargs="+", required=True, help="curated bike folders with views/ and gaussians/")
    ap.add_argument("--poses", type=int, default=6, help="random poses per bike (default 6)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--samples", type=int, default=16, help="Cycles samples of the Blender reference")
    ap.add_argument("--image", default=None, help="PNG: per bike, Blender | Gaussians (cropped, the largest view)")
    a = ap.parse_args(argv)
    for b in a.bikes:
        if not os.path.isfile(os.path.join(b, "gaussians", "frame.ply")):
            print(f"real_bikes.py: error: {b} has no trained gaussians/frame.ply", file=sys.stderr)
            return 2
    strips, table = [], ["| bike | poses | IoU mean (min) | box PSNR dB mean (min) |", "|---|---|---|---|"]
    for b in a.bikes:
        rows, (gt, pred) = check_bike(os.path.abspath(b), a.poses, a.seed, a.samples)
        iou, ps = np.array([r["iou"] for r in rows]), np.array([r["box_psnr"] for r in rows])
        table.append(f"| {os.path.basename(b)} | {len(rows)} | {iou.mean():.3f} ({iou.min():.3f}) | "
                     f"{ps.mean():.2f} ({ps.min():.2f}) |")
        strips.append((gt, pred))
    print("\n".join(table))
    if a.image:
        from PIL import Image
        h = 300
        tiles = []
        for gt, pred in strips:   # each pair scaled to one height, side by side with a gap
            w = int(round(gt.shape[1] * h / gt.shape[0]))
            pair = [np.asarray(Image.fromarray((x * 255).round().astype(np.uint8)).resize((w, h), Image.LANCZOS)) for x in (gt, pred)]
            tiles += [pair[0], np.full((h, 8, 3), 255, np.uint8), pair[1], np.full((h, 24, 3), 255, np.uint8)]
        img = Image.fromarray(np.concatenate(tiles[:-1], 1))
        tmp = a.image + ".tmp.png"
        img.save(tmp)
        os.replace(tmp, a.image)
    return 0


if __name__ == "__main__":
    sys.exit(main())

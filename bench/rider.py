"""Rider Gaussian avatar vs Blender at cycling poses (issue 5's ground truth) + re-pose speed.

Builds one avatar (splatting.rider.avatar_build, reduced training budget), then for poses from
`pedal_pose` at several (θp, θs) with a global yaw, and ring cameras around the posed body:
renders the LBS-posed Gaussians with the project's rasterizer and the LBS-posed mesh (the same
`pose_vertices`) with Blender (blender_scripts/render_rider.py --batch, sun lights turned with the
yaw), and compares mask IoU (alpha > 0.5) and PSNR (RGB on black, whole 512² image; the
rider-box PSNR is reported beside it). Keys: rider_gt = {poses, iou_mean, psnr_mean},
rider_repose_ms (LBS re-pose + concatenation with a 100k-Gaussian bike, per frame, median).
Table and worst-case picture beside results.json.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RIDER_ID = "m_adult_average_185"


def sample_poses(n, seed=0):
    """n poses spread over the crank circle, steering in ±25°, yaw over the full circle."""
    rng = np.random.default_rng(seed)
    k = np.arange(n)
    theta_p = (360.0 * k / n + rng.uniform(0, 360.0 / n, n)) % 360
    theta_s = rng.uniform(-25, 25, n)
    yaw = rng.permutation((360.0 * k / n + rng.uniform(0, 360.0 / n, n)) % 360)
    cams = rng.integers(0, 36, n)
    return theta_p, theta_s, yaw, cams


def ry(a):
    import torch
    c, s = math.cos(a), math.sin(a)
    return torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], dtype=torch.float64)


def posed_batch(rider, theta_p_deg, theta_s_deg, yaw_deg, pelvis_height=1.0):
    """(local_rotmats (B,24,3,3), root_trans (B,3)): pedal_pose turned by the yaw about the
    pelvis, pelvis at (0, pelvis_height, 0)."""
    import torch

    from splatting.rider.motion import pedal_pose

    rot, root, _ = pedal_pose(rider.joints, torch.tensor(np.radians(theta_p_deg)), torch.tensor(np.radians(theta_s_deg)))
    for b, y in enumerate(yaw_deg):
        rot[b, 0] = ry(math.radians(float(y))) @ rot[b, 0]  # the root turns about its own joint
    root = root + torch.tensor([0.0, pelvis_height, 0.0], dtype=torch.float64)
    return rot, root


def camera_json(cam):
    return {"K": cam.K.tolist(), "R": cam.R.tolist(), "T": cam.T.tolist()}


# Stills rendered before setup_lighting placed its suns at once (addon/core/render/render.py) were lit from
# straight above whenever the light was yawed; render_rider.py keeps any still it finds, so a folder
# without this stamp has its stills removed and rendered again.
STILLS_LIGHTING = "suns placed by setup_lighting, turned with the yaw"


def forget_stale_stills(gt_dir):
    """Remove gt_dir's gt_NNN.png stills unless gt_dir/lighting.json says they were lit as
    STILLS_LIGHTING, then stamp it. -> how many stills were removed."""
    from cyclist_formats.atomic import read_json_or_none, write_json

    stamp = os.path.join(gt_dir, "lighting.json")
    if read_json_or_none(stamp) == {"lighting": STILLS_LIGHTING}:
        return 0
    stale = [f for f in os.listdir(gt_dir) if f.startswith("gt_") and f.endswith(".png")]
    for f in stale:
        os.remove(os.path.join(gt_dir, f))
    write_json(stamp, {"lighting": STILLS_LIGHTING})
    return len(stale)


def posed_jobs(rider, rot, root, cams, gt_dir, extras=None):
    """Per pose: the LBS-posed mesh (posed_NNN.ply) and its ring camera (camera_NNN.json, framing the
    body) in gt_dir, plus gt_dir/jobs.json -> (jobs {mesh, camera, out} + that pose's `extras` dict,
    [Camera], the jobs file)."""
    from splatting.raster.camera import ring_camera
    from splatting.rider.body import export_rider, pose_vertices

    verts = pose_vertices(rider, rot, root)
    jobs, cameras = [], []
    for i, v in enumerate(verts):
        centre = (0.0, float((v[:, 1].min() + v[:, 1].max()) / 2), 0.0)
        cam = ring_camera(10.0 * int(cams[i]), centre, name=f"camera{int(cams[i]):04d}")
        cameras.append(cam)
        mesh = os.path.join(gt_dir, f"posed_{i:03d}.ply")
        export_rider(rider, mesh, vertices=v)
        cj = os.path.join(gt_dir, f"camera_{i:03d}.json")
        with open(cj, "w") as f:
            json.dump({cam.name: camera_json(cam), "orbit_centre": list(centre)}, f)
        jobs.append({"mesh": mesh, "camera": f"{cj}:{cam.name}", "out": os.path.join(gt_dir, f"gt_{i:03d}.png"),
                     **(extras[i] if extras else {})})
    job_file = os.path.join(gt_dir, "jobs.json")
    with open(job_file, "w") as f:
        json.dump(jobs, f, indent=1)
    return jobs, cameras, job_file


def repose_timing(avatar, rot, root, n_bike=100_000, reps=20):
    """Median ms of avatar.pose + Gaussians.cat with a 100k-Gaussian bike, one frame at a time."""
    import torch

    from splatting.gaussians.container import Gaussians

    g = torch.Generator().manual_seed(0)
    k = avatar.gaussians.sh.shape[1]
    bike = Gaussians(torch.randn(n_bike, 3, generator=g), torch.randn(n_bike, 4, generator=g),
                     torch.randn(n_bike, 3, generator=g) - 4, torch.randn(n_bike, generator=g),
                     torch.randn(n_bike, k, 3, generator=g))
    times = []
    with torch.no_grad():
        for i in range(reps + 2):
            b = i % len(rot)
            t = time.perf_counter()
            scene = Gaussians.cat([bike, avatar.pose(rot[b], root[b])])
            dt = time.perf_counter() - t
            if i >= 2:  # warm-up
                times.append(dt)
    assert len(scene) == n_bike + len(avatar)
    return float(np.median(times) * 1000), len(scene)


def run(results, out_dir, n_poses=12, seed=0, samples=None, iterations=2000, time_budget_s=480, rider_id=RIDER_ID):
    import torch

    from bench.compare import psnr, renders_for, score_png, side_by_side, write_table
    from splatting.raster.api import render_gaussians
    from splatting.rider.avatar import RiderAvatar
    from splatting.rider.avatar_build import build_avatar
    from splatting.rider.roster import load_rider

    torch.set_num_threads(1)
    av_dir = os.path.join(out_dir, "riders", rider_id)
    build = build_avatar(rider_id, av_dir, iterations=iterations, time_budget_s=time_budget_s, samples=samples)
    avatar = RiderAvatar.load(av_dir)
    rider = load_rider(rider_id)

    theta_p, theta_s, yaw, cams = sample_poses(n_poses, seed)
    rot, root = posed_batch(rider, theta_p, theta_s, yaw)
    from bench.provenance import RENDER_CODE, code_version

    # stills reused only for this rider, poses, cameras, samples and code (the roster mesh is posed by splatting/rider)
    gt_dir = renders_for(os.path.join(out_dir, "rider_gt"), {
        "rider": rider_id, "theta_p": theta_p.tolist(), "theta_s": theta_s.tolist(), "yaw": yaw.tolist(),
        "cameras": cams.tolist(), "samples": samples, "code": code_version(*RENDER_CODE, "splatting/rider")})
    if forget_stale_stills(gt_dir):
        print(f"  rider_gt: stills in {gt_dir} were lit before the sun fix: rendering them again", flush=True)
    jobs, cameras, job_file = posed_jobs(rider, rot, root, cams, gt_dir, [{"light_yaw_deg": float(y)} for y in yaw])
    cmd = [sys.executable, os.path.join(ROOT, "blender_scripts", "render_rider.py"), "--batch", job_file]
    if samples:
        cmd += ["--samples", str(samples)]
    subprocess.run(cmd, check=True)

    rows, renders = [], []
    with torch.no_grad():
        posed = avatar.pose(rot, root)
        posed = posed if isinstance(posed, list) else [posed]
        for i, (g, cam) in enumerate(zip(posed, cameras)):
            out = render_gaussians(g, cam)
            rgb = out["rgb"].clamp(0, 1).numpy().astype(np.float64)
            alpha = out["alpha"].numpy()
            iou, psnr_box, gt_rgb, box = score_png(jobs[i]["out"], rgb, alpha)
            rows.append({"theta_p_deg": float(theta_p[i]), "theta_s_deg": float(theta_s[i]), "yaw_deg": float(yaw[i]),
                         "camera": int(cams[i]), "iou": iou, "psnr": psnr(rgb, gt_rgb), "psnr_box": psnr_box})
            renders.append((gt_rgb, rgb, box))
    repose_ms, n_total = repose_timing(avatar, rot, root)

    iou = np.array([r["iou"] for r in rows])
    ps = np.array([r["psnr"] for r in rows])
    results["rider_gt"] = {"poses": len(rows), "iou_mean": float(iou.mean()), "psnr_mean": float(ps.mean())}
    results["rider_repose_ms"] = repose_ms
    worst = int(np.argmin(iou))
    gt_w, pred_w, box_w = renders[worst]
    side_by_side(gt_w, pred_w, os.path.join(out_dir, "rider_gt_worst.png"), box_w, zoom=2)
    tr = build.get("train") or {}
    lines = [f"Rider `{rider_id}`: {len(avatar)} Gaussians (SH degree {avatar.gaussians.sh_degree}), training "
             f"{tr.get('iterations')} iterations / {tr.get('wall_s')} s, held-out PSNR {tr.get('psnr')} dB over white; "
             f"skinning: {avatar.method}.", "",
             "| # | θp ° | θs ° | yaw ° | camera | IoU | PSNR dB (512²) | PSNR dB (rider box) |",
             "|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(rows):
        lines.append(f"| {i} | {r['theta_p_deg']:.1f} | {r['theta_s_deg']:.1f} | {r['yaw_deg']:.1f} | {r['camera']} "
                     f"| {r['iou']:.4f} | {r['psnr']:.2f} | {r['psnr_box']:.2f} |")
    lines.append(f"| mean | | | | | {iou.mean():.4f} | {ps.mean():.2f} | {np.mean([r['psnr_box'] for r in rows]):.2f} |")
    lines.append(f"\nrider_repose_ms: {repose_ms:.2f} ms per frame (LBS re-pose of {len(avatar)} Gaussians + "
                 f"concatenation with a 100k-Gaussian bike, {n_total} in total; median of 20, one thread).")
    lines.append(f"\nWorst IoU: pose {worst} (Blender | Gaussians | 4x |diff|, rider box, 2x) in rider_gt_worst.png.")
    write_table(out_dir, "rider_gt_table.md", lines)
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="rider avatar vs Blender + re-pose timing (standalone)")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
    ap.add_argument("--poses", type=int, default=12)
    ap.add_argument("--samples", type=int, default=None)
    ap.add_argument("--iterations", type=int, default=2000)
    ap.add_argument("--time-budget-s", type=float, default=480)
    ap.add_argument("--rider", default=RIDER_ID)
    a = ap.parse_args()
    sys.path.insert(0, ROOT)
    res = {}
    run(res, a.out, a.poses, samples=a.samples, iterations=a.iterations, time_budget_s=a.time_budget_s, rider_id=a.rider)
    print(json.dumps(res, indent=1))

"""Relit rider avatar vs Blender under a random sun that stays in the world (issue 16).

The rider_gt set-up (bench/rider.py: poses from pedal_pose at spread crank angles, steering and a
global yaw, ring cameras around the posed body, the LBS-posed mesh rendered by Blender), but the
studio lights are replaced by one random sun + sky per pose (splatting/relight/shading.random_light,
the lights do not turn with the body).  The avatar renders twice: relit (albedo, gloss and normals
turned by the skinning rotation, shaded per pixel: splatting/relight/avatar.py) and baked (today's
colours).  Keys: rider_relit = {box_psnr_mean, iou_mean, poses, baked_box_psnr_mean, baked_iou_mean}.
Box PSNR: RGB on black inside the union of both masks' box plus 8 px; IoU of alpha > 0.5.

    python bench/rider_relit.py --avatar AVATAR_DIR --out DIR [--poses 12]
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:  # run as a script (the bpy worker, a standalone run)
    sys.path.insert(0, ROOT)

from bench import worker_or_standalone  # noqa: E402



def blender_worker(job_path):
    """Under bpy: each posed mesh rendered under its own sun and sky."""
    sys.path.insert(0, ROOT)
    from dataclasses import replace

    from addon.core.render import render
    from addon.core.rider import rider_import

    from bench.relight import sun_and_sky

    from bench.compare import REFERENCE

    with open(job_path) as f:
        jobs = json.load(f)
    s = replace(render.RenderSettings(), threads=1, **REFERENCE)
    for i, job in enumerate(jobs):
        if os.path.isfile(job["out"]):
            continue
        render.setup_lighting = sun_and_sky(job["light"])  # render_rider_still calls it on its fresh scene
        rider_import.render_rider_still(job["mesh"], job["camera"], job["out"], s)
        print(f"  blender rider pose {i + 1}/{len(jobs)}", flush=True)


def run(results, out_dir, avatar_dir=None, n_poses=12, seed=0, progress=print):
    import torch

    from bench.compare import REFERENCE, renders_for, score_png, side_by_side, write_table
    from bench.provenance import RENDER_CODE, code_version, record, relight_fit_is_current, write_key
    from bench.relight import light_json
    from bench.rider import RIDER_ID, posed_batch, posed_jobs, sample_poses
    from cyclist_formats import bike_folder
    from splatting.raster.api import render_gaussians
    from splatting.relight.avatar import RIDER_ROUGHNESS, RelightableAvatar
    from splatting.relight.fit import RelightFitConfig, fit_file
    from splatting.relight.render import render_relit
    from splatting.relight.shading import random_light
    from splatting.rider.avatar import PLY_NAME
    from splatting.rider.avatar_build import build_avatar
    from splatting.rider.roster import load_rider

    torch.set_num_threads(1)
    if avatar_dir is None:  # the rider bench's avatar (built there, or here with its budget)
        avatar_dir = os.path.join(out_dir, "riders", RIDER_ID)
        build_avatar(RIDER_ID, avatar_dir, iterations=2000, time_budget_s=480)
    ply = os.path.join(avatar_dir, PLY_NAME)
    fit = None
    # refit unless the fit there was made from these Gaussians (file hash), views, settings and code
    current, key_path, fit_key = relight_fit_is_current(ply, os.path.join(avatar_dir, "views"), RelightFitConfig())
    if not current:
        fit = fit_file(os.path.join(avatar_dir, "views"), ply)
        write_key(key_path, fit_key)
        progress(f"  rider_relit: relight fit {fit}")
    ra = RelightableAvatar.load(avatar_dir)
    rider = load_rider(ra.avatar.rider_id or RIDER_ID)

    theta_p, theta_s, yaw, cams = sample_poses(n_poses, seed)  # rider_gt's poses and cameras
    rot, root = posed_batch(rider, theta_p, theta_s, yaw)
    rng = np.random.default_rng(seed + 17)
    lights = [random_light(rng) for _ in range(n_poses)]
    key = {"rider": ra.avatar.rider_id or RIDER_ID,  # Blender renders the roster body, not the avatar
           "theta_p": theta_p.tolist(), "theta_s": theta_s.tolist(), "yaw": yaw.tolist(), "cameras": cams.tolist(),
           "reference": REFERENCE, "lights": [light_json(light) for light in lights],
           "code": code_version(*RENDER_CODE, "splatting/rider")}   # the posed roster mesh comes from splatting/rider
    gt_dir = renders_for(os.path.join(out_dir, "rider_relit"), key)
    reused = all(os.path.isfile(os.path.join(gt_dir, f"gt_{i:03d}.png")) for i in range(n_poses))
    jobs, cameras, job_file = posed_jobs(rider, rot, root, cams, gt_dir, [{"light": light_json(light)} for light in lights])
    r = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", job_file], cwd=ROOT)
    if r.returncode:
        raise RuntimeError("rider_relit: the Blender worker failed")

    rows, shots = [], []
    with torch.no_grad():
        for i, ((g, albedo, normals, gloss), cam, light) in enumerate(zip(ra.pose(rot.float(), root.float()), cameras,
                                                                            lights)):
            # at its training resolution: no mip filter (it is for rendering below it; IoU 0.9707 with it)
            kw = {"roughness": RIDER_ROUGHNESS, "antialiased": False}
            relit = render_relit(g, albedo, normals, cam, light, gloss, shadows=True, **kw)
            flat = render_relit(g, albedo, normals, cam, light, gloss, **kw)
            baked = render_gaussians(g, cam)
            row = {"theta_p_deg": round(float(theta_p[i]), 1), "yaw_deg": round(float(yaw[i]), 1), "camera": int(cams[i]),
                   "sun_elevation_deg": round(float(np.degrees(np.arcsin(light.direction()[1]))), 1)}
            for key, out in (("relit", relit), ("noshadow", flat), ("baked", baked)):
                rgb = out["rgb"].clamp(0, 1).numpy().astype(np.float64)
                iou, ps, gt_rgb, box = score_png(jobs[i]["out"], rgb, out["alpha"].numpy())
                row[f"{key}_iou"], row[f"{key}_box_psnr"] = iou, ps
                if key == "relit":
                    shots.append((gt_rgb, rgb, box))
            rows.append(row)
    mean = lambda k: float(np.mean([r[k] for r in rows]))  # noqa: E731
    results["rider_relit"] = {"poses": len(rows), "reference": REFERENCE, "box_psnr_mean": mean("relit_box_psnr"), "iou_mean": mean("relit_iou"),
                              "baked_box_psnr_mean": mean("baked_box_psnr"), "baked_iou_mean": mean("baked_iou"),
                              "noshadow_box_psnr_mean": mean("noshadow_box_psnr"), "size_px": cameras[0].width, "gaussians": len(ra.avatar)}
    record(results, "rider_relit", "fresh", avatar=os.path.abspath(avatar_dir),
           blender_renders="reused (same key)" if reused else "rendered",
           relight_fit="fitted now" if fit else "reused (same key)")
    if fit:
        results["rider_relit"]["relight_fit"] = {k: fit.get(k) for k in ("wall_s", "heldout_albedo_psnr",
                                                                          "heldout_normal_err_deg")}
    worst = int(np.argmin([r["relit_box_psnr"] for r in rows]))
    side_by_side(*shots[worst][:2], os.path.join(out_dir, "rider_relit_worst.png"), shots[worst][2], zoom=1)
    lines = [f"Avatar {avatar_dir}: {len(ra.avatar)} Gaussians.", "",
             "| # | θp ° | yaw ° | camera | sun elev ° | relit IoU | relit box PSNR | no shadows | baked IoU | baked box PSNR |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(rows):
        lines.append(f"| {i} | {r['theta_p_deg']} | {r['yaw_deg']} | {r['camera']} | {r['sun_elevation_deg']} "
                     f"| {r['relit_iou']:.4f} | {r['relit_box_psnr']:.2f} | {r['noshadow_box_psnr']:.2f} | {r['baked_iou']:.4f} "
                     f"| {r['baked_box_psnr']:.2f} |")
    lines.append(f"| mean | | | | | {mean('relit_iou'):.4f} | {mean('relit_box_psnr'):.2f} | {mean('noshadow_box_psnr'):.2f} "
                 f"| {mean('baked_iou'):.4f} | {mean('baked_box_psnr'):.2f} |")
    write_table(out_dir, "rider_relit_table.md", lines)
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="relit rider avatar vs Blender under random suns (worker runs under bpy)")
    ap.add_argument("--worker", metavar="JOBS_JSON", help=argparse.SUPPRESS)
    ap.add_argument("--out", help="bench output folder")
    ap.add_argument("--avatar", help="an avatar folder (rider.ply, skinning.npz, views/ with passes); default: build one")
    ap.add_argument("--poses", type=int, default=12)
    a = worker_or_standalone(ap, blender_worker)
    if a is not None:
        if a.poses < 1:
            ap.error("--poses must be >= 1")
        if a.avatar and not os.path.isfile(os.path.join(a.avatar, "rider.ply")):
            sys.exit(f"error: no rider.ply in {a.avatar}")
        res = {}
        run(res, a.out, a.avatar, a.poses)
        print(json.dumps(res, indent=1))

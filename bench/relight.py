"""Relit bike vs Blender under a random sun that stays in the world (issue 16), on a tiny budget.

One procedural bike, its frame/steering/crank rendered at SIZE px from the 36-view ring with the
albedo and normal passes, each part trained small (MAX_GAUSSIANS, ITERATIONS) with the relight fit;
then for the same random poses and ring cameras as bike_gt (bench/bike_gt.sample_poses) and one
random sun + sky per pose (splatting/relight/shading.random_light), Blender renders the articulated
mesh lit by that sun (render_pose with lights not following the bike; converged: bench/compare.REFERENCE) and the Gaussians render
twice: relit (albedo + normal shaded per pixel) and baked (today's colours, trained under the studio
lights).  Keys: bike_relit = {box_psnr_mean, iou_mean, poses, baked_box_psnr_mean, baked_iou_mean},
relight_render_overhead = relit / baked render time - 1 (median of interleaved repeats per pose).
Box PSNR: RGB on black inside the union of both masks' box plus 8 px.  blender_coverage_box_psnr_mean:
the relit colour composited with Blender's alpha instead of the Gaussians' (what exact geometry
would give the same colours; coverage_cost).
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:  # run as a script (the bpy worker, a standalone run)
    sys.path.insert(0, ROOT)

from bench import worker_or_standalone  # noqa: E402

PY = sys.executable
PARTS = ("frame", "steering", "crank")
SIZE = 256             # the small bike's training views (when no trained bike is given)
GT_SIZE = 256          # the comparison
RENDER_SAMPLES = 4      # the training views (denoise off: Debian's 3.4 has no OIDN)
ITERATIONS = 600
MAX_GAUSSIANS = 4000


def _run(args, what):
    r = subprocess.run([PY, *args], cwd=ROOT, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{what} failed: {r.stderr[-1500:]}")
    return r


def prepare_bike(work, size=SIZE, progress=print):
    """make_bikes (1 bike) -> render_views at `size` with passes -> train + relight-fit each part."""
    bikes = os.path.join(work, "bikes")
    if not os.path.isdir(bikes) or not os.listdir(bikes):
        progress("  bike_relit: making one procedural bike")
        _run([os.path.join(ROOT, "blender_scripts", "make_bikes.py"), "--out", work, "--count", "1", "--seed", "0",
              "--no-extras"], "make_bikes")
    bike = os.path.join(bikes, sorted(os.listdir(bikes))[0])
    t = time.time()
    _run([os.path.join(ROOT, "blender_scripts", "render_views.py"), "--bike", bike, "--parts", ",".join(PARTS),
          "--size", str(size), "--samples", str(RENDER_SAMPLES), "--denoise", "NONE", "--threads", "1"], "render_views")
    progress(f"  bike_relit: views at {size} px with passes ({time.time() - t:.0f} s)")
    from cyclist_formats import bike_folder
    from cyclist_formats.typed_config import updated
    from splatting.training.strategy import DensifyConfig
    from splatting.training.trainer import TrainConfig, train

    train_stats = {}
    for part in PARTS:
        ply = bike_folder.gaussians_path(bike, part)
        if os.path.isfile(ply):  # trained before: (re)fit the relight channels only if they are missing or stale
            st = _fit_if_missing(bike, part, progress)
            if st is not None:
                train_stats[part] = st
            continue
        cfg = TrainConfig(iterations=ITERATIONS, progress=False, eval_every=100,
                          densify=updated(DensifyConfig(), max_gaussians=MAX_GAUSSIANS, stop=ITERATIONS // 2))
        # the relight fit as for every other bike (bike_fit_config, keyed: _fit_if_missing), so that a
        # second run finds it current instead of refitting with other settings
        m = train(bike_folder.views_dir(bike, part), ply, cfg)
        fit = _fit_if_missing(bike, part, progress) or {"reused": True}   # None: retrained to the same bytes
        train_stats[part] = {"psnr": m["psnr"], "gaussians": m["gaussians"], "train_s": m["wall_s"],
                             "relight_fit_s": fit.get("wall_s"), "albedo_psnr": fit.get("heldout_albedo_psnr"),
                             "gloss_psnr": fit.get("heldout_gloss_psnr"), "normal_err_deg": fit.get("heldout_normal_err_deg")}
        progress(f"  bike_relit: {part} {train_stats[part]}")
    return bike, train_stats


def sun_and_sky(light):
    """A setup_lighting replacement (runs under bpy): the studio lights removed, one sun and a
    uniform sky as `light` (light_json) says, fixed in the world."""
    import bpy

    from addon.core import frames
    from addon.core.render import render

    def setup(scene):
        for o in list(scene.objects):
            if o.type == "LIGHT":
                bpy.data.objects.remove(o)
        world = scene.world or bpy.data.worlds.new("sky")
        scene.world = world
        world.use_nodes = True
        bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
        bg.inputs["Color"].default_value = (*light["sky"], 1.0)
        bg.inputs["Strength"].default_value = 1.0
        sun = bpy.data.lights.new("relight_sun", "SUN")
        sun.energy = light["sun_strength"]
        sun.color = light["sun_colour"]
        sun.angle = 0.01
        obj = bpy.data.objects.new("relight_sun", sun)
        scene.collection.objects.link(obj)
        d = frames.to_blender(np.asarray(light["sun_direction"], float))
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = render._quat_z_to(d / np.linalg.norm(d))
    return setup


def light_json(light):
    """shading.Light -> the plain dict the Blender worker reads."""
    import torch
    return {"sun_direction": list(map(float, light.direction(torch.float64))), "sun_colour": list(light.sun_colour),
            "sun_strength": light.sun_strength, "sky": list(light.sky)}


def ring_camera_files(bike, cams, size, out_dir):
    """Ring cameras `cams` (indices) of the bike's frame views, rescaled to size px (same field of
    view) -> one {"K","R","T"} JSON file each in out_dir (what render_pose reads)."""
    with open(os.path.join(bike, "views", "frame", "cameras.json")) as f:
        ring_json = json.load(f)
    files = []
    for i, c in enumerate(cams):
        e = ring_json[f"camera{int(c):04d}"]
        k = size / (2 * e["K"][0][2])
        K = [[e["K"][0][0] * k, 0.0, size / 2], [0.0, e["K"][1][1] * k, size / 2], [0.0, 0.0, 1.0]]
        p = os.path.join(out_dir, f"camera_{i:03d}.json")
        with open(p, "w") as f:
            json.dump({"K": K, "R": e["R"], "T": e["T"]}, f)
        files.append(p)
    return files


def blender_worker(job_path):
    """Runs under bpy: per pose, the studio lights replaced by that pose's sun and sky."""
    sys.path.insert(0, ROOT)
    from dataclasses import replace

    from addon.core.render import render
    from addon.core.render.render_pose import render_pose

    with open(job_path) as f:
        job = json.load(f)
    s = replace(render.RenderSettings(), threads=1, **job["reference"])
    for i, (pose, cam, light) in enumerate(zip(job["poses"], job["cameras"], job["lights"])):
        out = os.path.join(job["out"], f"gt_{i:03d}.png")
        if os.path.isfile(out):
            continue
        render.setup_lighting = sun_and_sky(light)  # render_pose calls it after opening the bike
        render_pose(job["bike"], pose, cam, out, None, s, lights_follow=False)
        print(f"  blender pose {i + 1}/{len(job['poses'])}", flush=True)


def coverage_cost(gt_png, rgb, alpha, box):
    """How much of a render's error is its coverage (the Gaussians' geometry) rather than its colour:
    (box PSNR of the render's straight colour composited with Blender's alpha instead of its own,
    share of the box's squared error in the pixels whose masks (alpha > 0.5) disagree).  Pixels
    the render leaves uncovered (alpha < 0.02) have no colour of their own and stay black."""
    from PIL import Image

    from bench.compare import load_rgba, psnr

    gt_rgb, m_gt = load_rgba(gt_png)
    ga = np.asarray(Image.open(gt_png).convert("RGBA"))[..., 3].astype(np.float64) / 255
    straight = np.where(alpha[..., None] > 0.02, rgb / np.maximum(alpha, 0.02)[..., None], 0.0).clip(0, 1)
    x0, y0, x1, y1 = box
    err = ((rgb - gt_rgb) ** 2).sum(-1)[y0:y1, x0:x1]
    disagree = ((alpha > 0.5) != m_gt)[y0:y1, x0:x1]
    return (psnr((straight * ga[..., None])[y0:y1, x0:x1], gt_rgb[y0:y1, x0:x1]),
            float(err[disagree].sum() / max(float(err.sum()), 1e-12)))


def fit_missing(bike, progress=print):
    """Relight-fit the parts of a trained bike whose PART.relight.npz is missing or stale (relight-fit
    --bike's settings: bike_fit_config); {part: fit metrics}."""
    stats = {}
    for part in PARTS:
        st = _fit_if_missing(bike, part, progress)
        if st is not None:
            stats[part] = st
    return stats


def _fit_if_missing(bike, part, progress=print):
    """Relight-fit one trained part (bike_fit_config) unless its PART.relight.npz reads and was made
    from these Gaussians (file hash), views, settings and code (its .key.json, bench/provenance.py);
    its fit metrics, or None when the fit there is current."""
    from bench.provenance import relight_fit_is_current, write_key
    from cyclist_formats import bike_folder
    from splatting.relight.fit import bike_fit_config, fit_file

    ply, views, cfg = bike_folder.gaussians_path(bike, part), bike_folder.views_dir(bike, part), bike_fit_config()
    current, key_path, key = relight_fit_is_current(ply, views, cfg)
    if current:
        return None
    m = fit_file(views, ply, cfg)
    write_key(key_path, key)
    st = {k: m.get(k) for k in ("wall_s", "heldout_albedo_psnr", "heldout_gloss_psnr", "heldout_normal_err_deg")}
    progress(f"  bike_relit: {part} relight fit {st}")
    return st


def run_bench(results, out_dir, n_poses=None):
    """`make bench`: bike_gt's trained bike (out/bench/bikes, 512 px views) when it has the passes,
    compared at 256 px; otherwise the small bike built here."""
    from bench.bike_gt import find_bike
    from cyclist_formats import bike_folder

    bike, fallback = find_bike(os.path.join(out_dir, "bikes")), None
    if bike is None:
        fallback = f"no trained bike under {os.path.join(out_dir, 'bikes')}: the small bike built here"
    elif not all(os.path.isfile(bike_folder.pass_paths(bike_folder.views_dir(bike, p), "camera0000")["albedo"])
                 for p in PARTS):
        fallback = f"{bike} has no albedo/normal passes (views rendered before them): the small bike built here"
        bike = None
    if fallback:
        print(f"  bike_relit: {fallback}")
    rows = run(results, out_dir, n_poses, bike=bike)
    if fallback:
        from bench.provenance import record
        for k in ("bike_relit", "relight_render_overhead", "relight_shadow_overhead", "relight_render_ms"):
            if k in results:
                record(results, k, fallback=fallback)
    return rows


def run(results, out_dir, n_poses=None, seed=0, size=GT_SIZE, repeats=5, bike=None, progress=print):
    """bike: a trained bike folder (views with passes, gaussians/); None builds the small one.
    n_poses None: bike_gt's poses (bench/bike_gt.POSES, the issue's "same random poses")."""
    import torch

    from bench.bike_gt import POSES, sample_poses
    from bench.compare import REFERENCE, renders_for, score_png, side_by_side, write_table
    from cyclist_formats import bike_folder
    from splatting.raster.camera import load_cameras
    from splatting.raster.api import render_gaussians
    from splatting.relight.bike import RelightableBike
    from splatting.relight.render import render_relit
    from splatting.relight.shading import random_light

    torch.set_num_threads(1)
    work = os.path.join(out_dir, "relight")
    t0 = time.time()
    if bike is None:
        bike, train_stats = prepare_bike(work, SIZE, progress)
    else:
        bike, train_stats = os.path.abspath(bike), fit_missing(bike, progress)
    prep_s = time.time() - t0
    n_poses = n_poses or POSES
    poses, cams = sample_poses(n_poses, seed)
    rng = np.random.default_rng(seed + 16)
    lights = [random_light(rng) for _ in range(n_poses)]
    from bench.provenance import RENDER_CODE, bike_assets, code_version, file_hash
    key = {**bike_assets(bike), "frame_cameras": file_hash(os.path.join(bike_folder.views_dir(bike, "frame"), "cameras.json")),
           "poses": poses.tolist(), "cameras": cams.tolist(), "size": size, "reference": REFERENCE,
           "lights": [light_json(l) for l in lights], "code": code_version(*RENDER_CODE)}
    gt_dir = renders_for(os.path.join(work, f"gt_{os.path.basename(bike)}_{size}"), key)
    reused = all(os.path.isfile(os.path.join(gt_dir, f"gt_{i:03d}.png")) for i in range(n_poses))
    job = dict(key, cameras=ring_camera_files(bike, cams, size, gt_dir), out=gt_dir)
    job_path = os.path.join(gt_dir, "job.json")
    with open(job_path, "w") as f:
        json.dump(job, f)
    t = time.time()
    _run([__file__, "--worker", job_path], "blender ground truth")
    progress(f"  bike_relit: {n_poses} Blender renders at {size} px, {REFERENCE['samples']} samples "
             f"({time.time() - t:.0f} s)")

    rb = RelightableBike.load(bike)
    ring, _ = load_cameras(os.path.join(bike_folder.views_dir(bike, "frame"), "cameras.json"))
    # the mip filter is for rendering below the training resolution (at 512 px it cost IoU 0.952 -> 0.889),
    # and for parts trained with it (BikeModel.antialiased: baked, relit and their shadow maps alike)
    trained_aa = rb.model.antialiased
    aa = trained_aa or size < ring[0].width
    t = time.time()
    sky = rb.sky_visibility()  # once per bike (the sky's occlusion; shadow.sky_visibility), not timed per render
    sky_s = time.time() - t
    rows, shots, t_baked, t_relit, t_shadow = [], [], [], [], []
    with torch.no_grad():
        for i, (pose, c, light) in enumerate(zip(poses, cams, lights)):
            cam = ring[int(c)]
            cam = cam.scaled(size / cam.width) if cam.width != size else cam
            posed, albedo, normals, gloss = rb.pose(torch.tensor(pose, dtype=torch.float64))
            nview = rb.posed_normal_view(torch.tensor(pose, dtype=torch.float64))  # per pose, like the normals
            g = posed.gaussians.map(lambda x: x.contiguous())
            tb, tr, ts = [], [], []
            for _ in range(repeats):  # interleaved, so load changes hit all alike
                a = time.perf_counter()
                baked = render_gaussians(g, cam, antialiased=trained_aa, eps2d=rb.model.eps2d)
                b = time.perf_counter()
                flat = render_relit(g, albedo, normals, cam, light, gloss, antialiased=aa, static=rb.static,
                                    sky_visibility=sky, shadow_antialiased=trained_aa, normal_view=nview,
                                    eps2d=rb.model.eps2d)
                c2 = time.perf_counter()
                relit = render_relit(g, albedo, normals, cam, light, gloss, shadows=True, antialiased=aa,
                                     static=rb.static, sky_visibility=sky, shadow_antialiased=trained_aa,
                                     normal_view=nview, eps2d=rb.model.eps2d)
                ts.append(time.perf_counter() - c2)
                tr.append(c2 - b)
                tb.append(b - a)
            t_baked.append(np.median(tb))
            t_relit.append(np.median(tr))
            t_shadow.append(np.median(ts))
            row = {"pose": [round(float(v), 2) for v in pose], "camera": int(c),
                   "sun_elevation_deg": round(float(np.degrees(np.arcsin(light.direction()[1]))), 1)}
            for key, out in (("relit", relit), ("noshadow", flat), ("baked", baked)):
                rgb = out["rgb"].clamp(0, 1).numpy().astype(np.float64)
                iou, ps, gt_rgb, box = score_png(os.path.join(gt_dir, f"gt_{i:03d}.png"), rgb, out["alpha"].numpy())
                row[f"{key}_iou"], row[f"{key}_box_psnr"] = iou, ps
                if key == "relit":
                    shots.append((gt_rgb, rgb, box))
                    row["relit_box_psnr_blender_coverage"], row["mask_disagreement_err_share"] = coverage_cost(
                        os.path.join(gt_dir, f"gt_{i:03d}.png"), rgb, out["alpha"].numpy(), box)
            rows.append(row)
    mean = lambda k: float(np.mean([r[k] for r in rows]))  # noqa: E731
    worst = int(np.argmin([r["relit_box_psnr"] for r in rows]))
    side_by_side(*shots[worst][:2], os.path.join(out_dir, "bike_relit_worst.png"), shots[worst][2],
                 zoom=max(1, 384 // size))
    overhead = float(np.median(np.asarray(t_relit) / np.asarray(t_baked)) - 1)
    shadow_overhead = float(np.median(np.asarray(t_shadow) / np.asarray(t_baked)) - 1)
    results["bike_relit"] = {"poses": len(rows), "reference": REFERENCE, "box_psnr_mean": mean("relit_box_psnr"), "iou_mean": mean("relit_iou"),
                             "baked_box_psnr_mean": mean("baked_box_psnr"), "baked_iou_mean": mean("baked_iou"),
                             "noshadow_box_psnr_mean": mean("noshadow_box_psnr"),
                             # the geometry's share: the relit colour under Blender's own coverage
                             "blender_coverage_box_psnr_mean": mean("relit_box_psnr_blender_coverage"),
                             "mask_disagreement_err_share_mean": mean("mask_disagreement_err_share"), "size_px": size, "bike": os.path.basename(bike), "gaussians": len(rb.model),
                             "antialiased": trained_aa,
                             "prepare_s": round(prep_s, 1), "sky_visibility_s": round(sky_s, 1),
                             "train": train_stats}
    from bench.provenance import record
    for k in ("bike_relit", "relight_render_overhead", "relight_shadow_overhead", "relight_render_ms"):
        # Gaussians drawn and timed now; Blender's references and the parts' relight fits may be reused
        record(results, k, "fresh", bike=bike, blender_renders="reused (same key)" if reused else "rendered",
               relight_fits=f"fitted now: {sorted(train_stats)}" if train_stats else "reused (same key)")
    results["relight_render_overhead"] = overhead
    results["relight_shadow_overhead"] = shadow_overhead
    results["relight_render_ms"] = {"baked_median": 1000 * float(np.median(t_baked)),
                                    "relit_median": 1000 * float(np.median(t_relit)),
                                    "relit_shadows_median": 1000 * float(np.median(t_shadow))}
    lines = ["| # | pose p,s,X,Y,Z | camera | sun elev ° | relit IoU | relit box PSNR | no shadows | baked IoU | baked box PSNR |",
             "|---|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(rows):
        lines.append(f"| {i} | {', '.join(f'{v:.0f}' for v in r['pose'][:5])} | {r['camera']} | {r['sun_elevation_deg']} "
                     f"| {r['relit_iou']:.4f} | {r['relit_box_psnr']:.2f} | {r['noshadow_box_psnr']:.2f} | {r['baked_iou']:.4f} "
                     f"| {r['baked_box_psnr']:.2f} |")
    lines.append(f"| mean | | | | {mean('relit_iou'):.4f} | {mean('relit_box_psnr'):.2f} | {mean('noshadow_box_psnr'):.2f} "
                 f"| {mean('baked_iou'):.4f} | {mean('baked_box_psnr'):.2f} |")
    ms = results["relight_render_ms"]
    lines.append(f"\nRender time (median per pose of {repeats} interleaved repeats, {size} px, {len(rb.model)} Gaussians): "
                 f"baked {ms['baked_median']:.1f} ms, relit {ms['relit_median']:.1f} ms ({overhead:+.2f}), relit with "
                 f"shadows {ms['relit_shadows_median']:.1f} ms ({shadow_overhead:+.2f}). Worst pose (GT | relit | 4x |diff|) "
                 "in bike_relit_worst.png.")
    write_table(out_dir, "bike_relit_table.md", lines)
    return rows


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="relit bike vs Blender under random suns (worker runs under bpy)")
    ap.add_argument("--worker", metavar="JOB_JSON")
    ap.add_argument("--out", help="bench output folder (standalone run)")
    ap.add_argument("--poses", type=int, help="random poses (default: bike_gt's, 20)")
    ap.add_argument("--size", type=int, default=GT_SIZE, help="comparison image size in px (default %(default)s)")
    ap.add_argument("--bike", help="a trained bike folder (views with passes + gaussians/); default: build a small one")
    a = worker_or_standalone(ap, blender_worker)
    if a is not None:
        if a.bike and not os.path.isfile(os.path.join(a.bike, "gaussians", "frame.ply")):
            sys.exit(f"error: {a.bike}: no trained gaussians/frame.ply")
        if (a.poses is not None and a.poses < 1) or not 16 <= a.size <= 4096:
            sys.exit("error: --poses must be >= 1 and --size in 16..4096")
        res = {}
        run(res, a.out, n_poses=a.poses, size=a.size, bike=a.bike)
        print(json.dumps({k: res[k] for k in ("bike_relit", "relight_render_overhead", "relight_render_ms")}, indent=1))

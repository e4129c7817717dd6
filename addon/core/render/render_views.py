"""The render_views stage: a bike folder -> views/<part>/ for each part (and each sub-part the bike
has: front_wheel, rear_wheel, pedal_left, pedal_right; docs/contract.md) and the whole bike."""
import os
from dataclasses import replace

from . import render
from ..contract import UserError, bike_folder

ALL_PARTS = bike_folder.PARTS + bike_folder.SUB_PARTS + (render.WHOLE,)
# the keypoints a sub-part's views carry: its axle or its pedal centre, and the rear contact
# point.  The axles (in the hub, between the dropouts) and the contact point (on the tyre) lie on
# the wheel only: with wheel sub-parts the frame's and steering's views leave them out (they fell
# off those masks, measured); a pedal keypoint stays on the crank's too (its spindle runs through it)
SUB_PART_KEYPOINTS = {"front_wheel": ["front_axle"], "rear_wheel": ["rear_axle", "ground"],
                      "pedal_left": ["pedal_left"], "pedal_right": ["pedal_right"]}
ON_SUB_PART_ONLY = {"ground": "rear_wheel", "rear_axle": "rear_wheel", "front_axle": "front_wheel"}
# Training views get more samples than a one-off render (RenderSettings' 16): on the city bike's
# frame (256², 800 iterations, scored against 1024-spp renders of the held-out cameras) 16 spp +
# denoising gave 32.45 dB box PSNR, 128 spp + denoising 32.95 dB, 64 / 128 spp without denoising
# 33.02 / 32.98 dB; 128 spp costs ~2.6x the render time of 16 (adaptive sampling stops early), a
# one-time cost per asset. docs/training.md, "Training views".
TRAINING_SAMPLES = 128


def parse_parts(spec, available):
    if spec in (None, "", "all"):
        return [p for p in ALL_PARTS if p in available or p == render.WHOLE]
    parts = [p.strip() for p in spec.split(",") if p.strip()]
    for p in parts:
        if p not in ALL_PARTS:
            raise UserError(f"unknown part '{p}' (choose from {', '.join(ALL_PARTS)} or 'all')")
        if p != render.WHOLE and p not in available:
            raise UserError(f"this bike has no '{p}' part (it has {', '.join(sorted(available))})")
    return parts


def parse_views(spec, n=36):
    if spec in (None, "", "all"):
        return None
    try:
        views = [int(v) for v in spec.split(",")]
    except ValueError:
        raise UserError(f"--views must be comma-separated integers, got '{spec}'")
    bad = [v for v in views if not 0 <= v < n]
    if bad:
        raise UserError(f"view index {bad[0]} out of range 0..{n - 1}")
    return views


def render_bike(bike_dir, parts="all", views=None, samples=None, denoise=None, size=None, threads=2,
                progress=print, adaptive_threshold=None):
    from ..bike_asset import open_bike  # opens bike.blend; UserError if missing/unreadable

    if not os.path.isdir(bike_dir):
        raise UserError(f"bike folder not found: {bike_dir}")
    view_list = parse_views(views)
    bike = open_bike(bike_dir)
    part_objs = bike["parts"]
    chosen = parse_parts(parts, set(part_objs))
    settings = render.RenderSettings(threads=threads, samples=TRAINING_SAMPLES)
    if samples is not None:
        if samples < 1:
            raise UserError("--samples must be >= 1")
        settings = replace(settings, samples=samples)
    if denoise is not None:
        settings = replace(settings, denoise=denoise)
    if adaptive_threshold is not None:
        if not adaptive_threshold >= 0:
            raise UserError("--adaptive-threshold must be >= 0 (0: adaptive sampling off)")
        settings = replace(settings, adaptive_threshold=adaptive_threshold)
    if size is not None:
        if size < 16:
            raise UserError("--size must be >= 16")
        settings = replace(settings, size=size)

    import bpy

    scene = bpy.context.scene
    render.configure_cycles(scene, settings)
    render.setup_lighting(scene)
    kp = bike["keypoints"]
    # which keypoints each part carries (open_bike has read this file already: it is valid JSON)
    kp_parts = bike_folder.read_json(os.path.join(bike_dir, "keypoints.json")).get("parts", {})
    results = {}
    for part in chosen:
        if part == render.WHOLE:
            objs, names = list(part_objs.values()), list(kp)
        else:
            objs, names = [part_objs[part]], kp_parts.get(part, SUB_PART_KEYPOINTS.get(part, []))
            names = [k for k in names if part in bike_folder.SUB_PARTS or ON_SUB_PART_ONLY.get(k) not in part_objs]
        part_kp = {k: kp[k] for k in names if k in kp}
        out = os.path.join(bike_dir, "views", part)
        results[part] = render.render_part(scene, objs, out, part_kp, views=view_list, settings=settings,
                                           progress=progress, label=f"{os.path.basename(os.path.normpath(bike_dir))}/{part}")
    return results

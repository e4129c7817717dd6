"""Imported riders, posed on a bike by the IK, drawn with the bike (the pictures of the rider-import contact sheet).

    python blender_scripts/render_rider_on_bike.py --bike BIKE_DIR --jobs JOBS.json [--size 360 --samples 16]

JOBS.json: [{"rider": posed rider.npz (canonical frame), "out": FILE.png}, ...], written by
bench/rider_import_sheet.py.  The bike is BIKE_DIR/bike.blend at its rest pose (crank angle 0), the
rider its posed rider file with its textures (rider_import.import_rider), seen from the rider's left.
A job whose FILE.png exists is skipped.
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import UserError, run_main  # noqa: E402

CAMERA_CANONICAL = (0.35, 1.05, -3.4)   # left of the bike, a little ahead and above the saddle
TARGET_CANONICAL = (0.05, 0.8, 0.0)


def main(argv):
    p = argparse.ArgumentParser(prog="render_rider_on_bike.py", description=__doc__.splitlines()[0])
    p.add_argument("--bike", required=True)
    p.add_argument("--jobs", required=True)
    p.add_argument("--size", type=int, default=360)
    p.add_argument("--samples", type=int, default=16)
    args = p.parse_args(argv)
    blend = os.path.join(args.bike, "bike.blend")
    if not os.path.isfile(blend):
        raise UserError(f"--bike {args.bike}: no bike.blend")
    jobs = json.load(open(args.jobs))
    import bpy
    from mathutils import Vector

    from addon.core import frames
    from addon.core.render import render
    from addon.core.curation.importers import import_model
    from addon.core.rider.rider_import import import_rider
    from addon.core.scene import reset_scene
    for k, job in enumerate(jobs):
        if os.path.isfile(job["out"]):
            continue
        scene = reset_scene()
        render.configure_cycles(scene, render.RenderSettings(samples=args.samples, size=args.size))
        render.setup_lighting(scene)
        import_model(blend)
        import_rider(job["rider"], scene=scene)
        cam = render.ensure_camera(scene, args.size, 0.9 * args.size)
        eye = Vector(frames.to_blender(CAMERA_CANONICAL).tolist())
        at = Vector(frames.to_blender(TARGET_CANONICAL).tolist())
        cam.location = eye
        cam.rotation_mode = "QUATERNION"
        cam.rotation_quaternion = (at - eye).to_track_quat("-Z", "Y")
        scene.render.film_transparent = False
        if scene.world is None:
            scene.world = bpy.data.worlds.new("sheet")
        scene.world.color = (0.9, 0.9, 0.9)
        bpy.context.view_layer.update()
        render.render_atomic(scene, job["out"], derive=False)
        print(f"render_rider_on_bike: {k + 1}/{len(jobs)} {job['out']}", flush=True)
    return 0


if __name__ == "__main__":
    run_main(main, "render_rider_on_bike.py")

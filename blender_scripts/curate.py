"""Curate an imported bicycle model into a bike folder (the layout make_bikes writes).

    blender -b -P blender_scripts/curate.py -- --input MODEL --out OUT/bikes/ID [--keypoints auto|FILE.json] [--wheel-diameter M]
    .venv/bin/python blender_scripts/curate.py --input MODEL --out OUT/bikes/ID

MODEL: .glb .gltf .obj .fbx .ply .blend.  Removes what is not the bike, finds the wheels, puts
the bike in the canonical pose at real scale (tyre diameter --wheel-diameter, default 0.7 m),
estimates and validates the keypoints (or reads them, canonical frame, from FILE.json), splits
frame / steering / crank, rigs and saves.  Runs the annotator panel's operators, headless.
"""
import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from addon.core.script import UserError, run_main  # noqa: E402


def parse(argv):
    p = argparse.ArgumentParser(prog="curate.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--input", required=True, help="model file (.glb .gltf .obj .fbx .ply .blend)")
    p.add_argument("--out", required=True, help="bike folder to write, e.g. OUT/bikes/my_bike")
    p.add_argument("--keypoints", default="auto", help="'auto' (default) or a JSON file of canonical keypoints")
    p.add_argument("--wheel-diameter", type=float, default=0.7, help="tyre outer diameter in metres (default 0.7)")
    p.add_argument("--allow-problems", action="store_true", help="save even if keypoint validation fails")
    return p.parse_args(argv)


def _op(call, **kw):
    """Run an add-on operator; its ERROR report becomes a UserError (one stderr line)."""
    try:
        res = call(**kw)
    except RuntimeError as e:
        msg = " ".join(str(e).split())
        raise UserError(msg[len("Error: "):] if msg.startswith("Error: ") else msg) from None
    if "FINISHED" not in res:
        raise UserError(f"{call.idname_py()} was cancelled")
    return res


def main(argv):
    args = parse(argv)
    from cyclist_formats import checks
    checks.input_file("input", args.input)
    checks.output_dir("out", args.out)
    if not os.path.isfile(args.input):
        raise UserError(f"model file not found: {args.input}")
    if not (args.wheel_diameter > 0 and args.wheel_diameter < 10):
        raise UserError(f"--wheel-diameter must be in (0, 10) metres, got {args.wheel_diameter}")
    if args.keypoints != "auto" and not os.path.isfile(args.keypoints):
        raise UserError(f"keypoints file not found: {args.keypoints}")
    import bpy

    import addon
    from addon.core.scene import reset_scene

    reset_scene()
    try:
        addon.register()
    except ValueError:  # already registered in this process
        pass
    _op(bpy.ops.articcyc.import_model, filepath=os.path.abspath(args.input))
    _op(bpy.ops.articcyc.auto_curate, wheel_diameter=args.wheel_diameter,
        keypoints_file="" if args.keypoints == "auto" else os.path.abspath(args.keypoints))
    sc = bpy.context.scene
    for p in sc.articcyc_problems:
        print(f"curate.py: warning: {p.name}", file=sys.stderr)
    _op(bpy.ops.articcyc.save_bike, directory=os.path.abspath(args.out), allow_problems=args.allow_problems)
    print(f"curate.py: wrote {args.out}", flush=True)
    return 0


if __name__ == "__main__":
    run_main(main, "curate.py")

"""Curate an imported bicycle model into a bike folder (the layout make_bikes writes).

    blender -b -P blender_scripts/curate.py -- --input MODEL --out OUT/bikes/ID [--keypoints auto|FILE.json] [--wheel-diameter M]
    .venv/bin/python blender_scripts/curate.py --input MODEL --out OUT/bikes/ID

A model that is not a two-wheeler is refused with one line naming the failed check; a model
whose keypoints or split fail is saved as OUT.partial.blend for the annotator panel to finish.

MODEL: .glb .gltf .obj .fbx .ply .stl .blend.  Removes what is not the bike, finds the wheels, puts
the bike in the canonical pose at real scale (tyre diameter --wheel-diameter, else from every size cue),
estimates and validates the keypoints (or reads them, canonical frame, from FILE.json), splits
frame / steering / crank, rigs and saves: the functions the annotator panel's operators wrap.
"""
import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from addon.core.script import UserError, run_main  # noqa: E402


def parse(argv):
    p = argparse.ArgumentParser(prog="curate.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--input", required=True, help="model file (.glb .gltf .obj .fbx .ply .stl .blend)")
    p.add_argument("--out", required=True, help="bike folder to write, e.g. OUT/bikes/my_bike")
    p.add_argument("--keypoints", default="auto", help="'auto' (default) or a JSON file of canonical keypoints")
    p.add_argument("--wheel-diameter", default="auto",
                   help="tyre outer diameter in metres, or 'auto' (default: from the vehicle's class, the file's "
                        "units, its wheelbase, bar and seat heights; refused with the figures when they disagree)")
    p.add_argument("--no-sub-parts", action="store_true",
                   help="keep the wheels and pedals inside frame / steering / crank (no spinning wheels)")
    p.add_argument("--allow-problems", action="store_true", help="save even if keypoint validation fails")
    return p.parse_args(argv)


def main(argv):
    args = parse(argv)
    from cyclist_formats import checks
    checks.input_file("input", args.input)
    checks.output_dir("out", args.out)
    if not os.path.isfile(args.input):
        raise UserError(f"model file not found: {args.input}")
    if args.wheel_diameter == "auto":
        wheel = 0.0
    else:
        try:
            wheel = float(args.wheel_diameter)
        except ValueError:
            wheel = float("nan")
        if not (0 < wheel < 10):
            raise UserError(f"--wheel-diameter must be 'auto' or in (0, 10) metres, got {args.wheel_diameter}")
    if args.keypoints != "auto" and not os.path.isfile(args.keypoints):
        raise UserError(f"keypoints file not found: {args.keypoints}")
    from addon.core.curation import importers
    from addon.core.curation.curate_scene import auto_curate
    from addon.core.curation.keypoint_empties import read_keypoints_file
    from addon.core.curation.saving import save, save_partial
    from addon.core.procedural.layout import KEYPOINT_NAMES
    from addon.core.scene import reset_scene
    from addon.core.curation.sub_part_split import add_sub_parts
    import bpy

    reset_scene()
    model = os.path.abspath(args.input)
    importers.import_model(model)
    kp = None if args.keypoints == "auto" else read_keypoints_file(os.path.abspath(args.keypoints))
    probs = list(auto_curate(None if wheel == 0.0 else wheel, kp, source_path=model).problems)
    for p in probs:
        print(f"curate.py: warning: {p}", file=sys.stderr)
    missing = [k for k in KEYPOINT_NAMES if bpy.data.objects.get(f"kp.{k}") is None]
    split_failed = any(p.startswith("split:") for p in probs)
    if probs and (not args.allow_problems or missing or split_failed):
        # the annotator finishes it: open the partial curation, the panel lists the problems
        partial = save_partial(os.path.abspath(args.out).rstrip("/") + ".partial.blend")
        raise UserError(f"{probs[0]}" + (f" (+{len(probs) - 1} more)" if len(probs) > 1 else "")
                        + f"; partial curation saved to {partial}: open it in Blender, ArticCyclists panel "
                          f"> Resume partial curation")
    save(os.path.abspath(args.out).rstrip("/\\"), args.allow_problems)
    if not args.no_sub_parts:  # wheels and pedal bodies as their own pieces (docs/contract.md "Sub-parts")
        add_sub_parts(os.path.abspath(args.out))
    print(f"curate.py: wrote {args.out}", flush=True)
    return 0


if __name__ == "__main__":
    run_main(main, "curate.py")

"""Generate the procedural bike library: OUT/bikes/<bike_id>/{bike.blend, keypoints.json, meta.json}.

    blender -b -P blender_scripts/make_bikes.py -- --out OUT --count 23 --seed 0
    .venv/bin/python blender_scripts/make_bikes.py --out OUT --count 23 --seed 0

Bicycles cycle through the styles of blend_assets/bike_styles.yaml (road, mountain, city, bmx,
kids, gravel, cruiser), plus one kick scooter and one motorcycle unless --no-extras.  The same
seed gives the same bikes; a bike folder that is already complete is skipped.  Bicycles get wheel
and pedal sub-parts (docs/contract.md "Sub-parts": wheels that spin, pedals that stay level) unless
--no-sub-parts.
"""
import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from addon.core.script import UserError, run_main  # noqa: E402


def parse(argv):
    p = argparse.ArgumentParser(prog="make_bikes", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output root; bikes go to OUT/bikes/<bike_id>/")
    p.add_argument("--count", type=int, default=23, help="number of bicycles (default 23)")
    p.add_argument("--seed", type=int, default=0, help="library seed (default 0)")
    p.add_argument("--no-extras", action="store_true", help="skip the kick scooter and the motorcycle")
    p.add_argument("--no-sub-parts", action="store_true",
                   help="keep the wheels and pedals inside frame / steering / crank (no spinning wheels)")
    p.add_argument("--styles", default=None, help="YAML of style ranges (default blend_assets/bike_styles.yaml)")
    return p.parse_args(argv)


def main(argv):
    args = parse(argv)
    from cyclist_formats import bike_folder, checks
    checks.output_dir("out", args.out)
    checks.integer("count", args.count, 0, 10_000)
    checks.integer("seed", args.seed, 0)
    if args.count == 0 and args.no_extras:
        raise UserError("--count 0 with --no-extras makes no bikes")
    if args.styles is not None:
        checks.input_file("styles", args.styles)
    if args.count < 0:
        raise UserError(f"--count must be >= 0, got {args.count}")
    import bpy
    from addon.core import bike_asset
    from addon.core.procedural import build, layout, spec as specs
    from addon.core.scene import reset_scene

    styles = specs.load_styles(args.styles) if args.styles else specs.load_styles()
    plan = specs.library_plan(args.count, args.seed, not args.no_extras, styles)
    root = os.path.join(args.out, "bikes")
    try:
        os.makedirs(root, exist_ok=True)
    except OSError as e:
        raise UserError(f"cannot create {root}: {e.strerror}") from None
    t_all = time.time()
    for i, (style, number) in enumerate(plan):
        bike_id = f"{style}_{number:02d}"
        out_dir = os.path.join(root, bike_id)
        tag = f"[{i + 1}/{len(plan)}] {bike_id}"
        if bike_asset.is_complete(out_dir):
            print(f"{tag}: complete, skipped", flush=True)
            continue
        t0 = time.time()
        spec = specs.sample_spec(style, number, args.seed, styles)
        reset_scene()
        res = build.build_bike(spec, sub_parts=not args.no_sub_parts)
        meta = {
            "bike_id": bike_id, "generator": "procedural", "style": style, "seed": args.seed,
            "rideable": spec["rideable"], "has_crank": "crank" in res["parts"],
            "dimensions": build.dimensions(spec, res["layout"]),
            "blender_version": bpy.app.version_string,
            "triangles": res["triangles"],
            "sub_parts": [p for p in bike_folder.SUB_PARTS if p in res["parts"]],
            "keypoint_notes": KEYPOINT_NOTES.get(spec["rideable"], ""),
            "spec": spec,
        }
        if res["gear_ratio"] is not None:
            meta["gear_ratio"] = res["gear_ratio"]  # wheel turns per crank turn (chainring / middle cog)
        bike_asset.save_bike(out_dir, spec, res["keypoints"], layout.part_keypoints(spec), meta)
        tri = sum(res["triangles"].values())
        print(f"{tag}: {tri} triangles, wheelbase {meta['dimensions']['wheelbase_m']:.3f} m, "
              f"{time.time() - t0:.1f} s", flush=True)
    print(f"make_bikes: {len(plan)} bikes in {root} ({time.time() - t_all:.1f} s)", flush=True)
    return 0


KEYPOINT_NOTES = {
    "bicycle": "docs/contract.md keypoints; drop bars: handle_* at the brake hoods, other bars: grip centres",
    "kick_scooter": "no saddle or crank: seat = rear foot spot on the deck top, crank_axle = deck centre, "
                    "pedal_left/right = foot spots on the deck (frame part)",
    "motorcycle": "no crank: crank_axle = midpoint of the footpeg axis, pedal_left/right = footpeg "
                  "centres (frame part); steer_top/bottom on the steering axis at the triple clamps",
}


if __name__ == "__main__":
    run_main(main, "make_bikes")

"""Cut a bike folder's wheels and pedal bodies out of its parts as sub-parts that spin and stay level.

    blender -b -P blender_scripts/add_sub_parts.py -- --bike OUT/bikes/ID [--gear-ratio 2.6]
    python blender_scripts/add_sub_parts.py --bike OUT/bikes/ID

For a curated bike (curate.py runs it unless --no-sub-parts) or a procedural one made with
--no-sub-parts: bike.blend gets the objects front_wheel, rear_wheel, pedal_left, pedal_right and a
rig that spins the wheels with theta_p x gear ratio and keeps the pedals level; meta.json gets
"sub_parts" and "gear_ratio" (docs/contract.md "Sub-parts").  Render the views and train again.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import run_main  # noqa: E402


def parse(argv):
    p = argparse.ArgumentParser(prog="add_sub_parts.py", description=__doc__.splitlines()[0])
    p.add_argument("--bike", required=True, help="bike folder (holds bike.blend, keypoints.json, meta.json)")
    p.add_argument("--gear-ratio", type=float, default=None,
                   help="wheel turns per crank turn (default: meta.json's, else 2.6, a 44/17 gear)")
    return p.parse_args(argv)


def main(argv):
    args = parse(argv)
    from cyclist_formats import checks
    checks.input_dir("bike", args.bike)
    checks.number("gear_ratio", args.gear_ratio, lo=0.5, hi=8.0)
    from addon.core.curation.sub_part_split import add_sub_parts

    add_sub_parts(args.bike, gear_ratio=args.gear_ratio)
    return 0


if __name__ == "__main__":
    run_main(main, "add_sub_parts.py")

"""Pose a bike's articulated mesh with the 8-DoF pose and render it: the ground-truth oracle.

    blender -b -P blender_scripts/render_pose.py -- --bike OUT/bikes/ID --pose "p,s,X,Y,Z,tx,ty,tz" \
        --camera cameras.json:camera0007 --out FILE.png [--keypoints-out FILE.json]

Angles in degrees, translations in metres (docs/contract.md).  Writes FILE.png (RGBA), FILE_mask.png
(alpha > 0.5) and FILE_rgb.jpg (RGB on black).
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import UserError, run_main  # noqa: E402


def main(argv):
    p = argparse.ArgumentParser(prog="render_pose.py", description=__doc__.splitlines()[0])
    p.add_argument("--bike", required=True)
    p.add_argument("--pose", required=True, help="p,s,X,Y,Z,tx,ty,tz (degrees, metres)")
    p.add_argument("--camera", required=True, help="cameras.json:cameraNNNN, or a JSON file with one K/R/T")
    p.add_argument("--out", required=True, help="output RGBA .png")
    p.add_argument("--keypoints-out", help="write the armature's posed keypoints (canonical frame) here")
    p.add_argument("--samples", type=int, default=None)
    p.add_argument("--lights", choices=["follow", "world"], default="follow",
                   help="sun lights move with the bike's global pose (default) or stay in the world")
    args = p.parse_args(argv)
    from cyclist_formats import checks
    checks.input_dir("bike", args.bike)
    checks.count("samples", args.samples, hi=1 << 16)
    checks.output_file("out", args.out, (".png",))
    checks.output_file("keypoints_out", args.keypoints_out, (".json",))
    from dataclasses import replace

    from addon.core import render, render_pose

    if not os.path.isdir(args.bike):
        raise UserError(f"no bike folder: {args.bike}")
    pose = render_pose.parse_pose(args.pose)
    s = render.RenderSettings()
    if args.samples:
        s = replace(s, samples=args.samples)
    render_pose.render_pose(args.bike, pose, args.camera, args.out, args.keypoints_out, s, args.lights == "follow")
    return 0


if __name__ == "__main__":
    run_main(main, "render_pose.py")

"""Pose a bike's articulated mesh with the 8-DoF pose and render it: the ground-truth oracle.

    blender -b -P blender_scripts/render_pose.py -- --bike OUT/bikes/ID --pose "p,s,X,Y,Z,tx,ty,tz" \
        --camera cameras.json:camera0007 --out FILE.png [--keypoints-out FILE.json]

Angles in degrees, translations in metres (docs/contract.md).  Writes FILE.png (RGBA), FILE_mask.png
(alpha > 0.5) and FILE_rgb.jpg (RGB on black).

    ... render_pose.py -- --bike OUT/bikes/ID --batch JOBS.json [--samples N --denoise FAST]

renders many poses in one Blender process (the posed training views of splatting/bike/posed_train.py):
JOBS.json is a list of {"pose": [8 numbers], "camera": "cameras.json:cameraNNNN", "out": "FILE.png"};
a job whose FILE.png exists is skipped (resumable), and each one prints a progress line.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import UserError, run_main  # noqa: E402


def main(argv):
    p = argparse.ArgumentParser(prog="render_pose.py", description=__doc__.splitlines()[0])
    p.add_argument("--bike", required=True)
    p.add_argument("--pose", help="p,s,X,Y,Z,tx,ty,tz (degrees, metres)")
    p.add_argument("--camera", help="cameras.json:cameraNNNN, or a JSON file with one K/R/T")
    p.add_argument("--out", help="output RGBA .png")
    p.add_argument("--batch", help="a JSON list of {pose, camera, out} jobs instead of --pose/--camera/--out")
    p.add_argument("--denoise", choices=["NONE", "FAST", "BALANCED", "HIGH"], default=None,
                   help="OpenImageDenoise (default: the renderer's, FAST)")
    p.add_argument("--keypoints-out", help="write the armature's posed keypoints (canonical frame) here")
    p.add_argument("--samples", type=int, default=None)
    p.add_argument("--threads", type=int, default=None,
                   help="Cycles CPU threads (default: the renderer's, 2); the image does not depend on it")
    p.add_argument("--lights", choices=["follow", "world"], default="follow",
                   help="sun lights move with the bike's global pose (default) or stay in the world")
    args = p.parse_args(argv)
    from cyclist_formats import checks
    checks.input_dir("bike", args.bike)
    checks.count("samples", args.samples, hi=1 << 16)
    if args.threads is not None:
        checks.threads("threads", args.threads)
    if args.batch:
        if args.pose or args.camera or args.out or args.keypoints_out:
            raise UserError("--batch replaces --pose, --camera, --out and --keypoints-out")
        jobs = read_jobs(args.batch)
    else:
        if not (args.pose and args.camera and args.out):
            raise UserError("--pose, --camera and --out are required (or --batch)")
        checks.output_file("out", args.out, (".png",))
        checks.output_file("keypoints_out", args.keypoints_out, (".json",))
    from dataclasses import replace

    from addon.core.render import render, render_pose

    if not os.path.isdir(args.bike):
        raise UserError(f"no bike folder: {args.bike}")
    s = render.RenderSettings()
    if args.samples:
        s = replace(s, samples=args.samples)
    if args.denoise:
        s = replace(s, denoise=args.denoise)
    if args.threads:
        s = replace(s, threads=args.threads)
    if not args.batch:
        pose = render_pose.parse_pose(args.pose)
        render_pose.render_pose(args.bike, pose, args.camera, args.out, args.keypoints_out, s, args.lights == "follow")
        return 0
    todo = [j for j in jobs if not os.path.isfile(j["out"])]
    for k, j in enumerate(todo):
        os.makedirs(os.path.dirname(os.path.abspath(j["out"])), exist_ok=True)
        render_pose.render_pose(args.bike, j["pose"], j["camera"], j["out"], None, s, args.lights == "follow")
        print(f"render_pose: {k + 1}/{len(todo)} {j['out']}", flush=True)
    return 0


def read_jobs(path):
    """--batch's JSON: a list of {"pose": 8 finite numbers, "camera": str, "out": "*.png"}; UserError otherwise."""
    import math

    from cyclist_formats.bike_folder import read_json

    jobs = read_json(path, "batch jobs")
    if not isinstance(jobs, list) or not jobs:
        raise UserError(f"{path}: expected a non-empty JSON list of jobs")
    for i, j in enumerate(jobs):
        ok = (isinstance(j, dict) and isinstance(j.get("camera"), str) and isinstance(j.get("out"), str)
              and j["out"].endswith(".png") and isinstance(j.get("pose"), list) and len(j["pose"]) == 8
              and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in j["pose"]))
        if not ok:
            raise UserError(f"{path}: job {i} needs pose (8 finite numbers), camera (string) and out (*.png)")
    return jobs


if __name__ == "__main__":
    run_main(main, "render_pose.py")

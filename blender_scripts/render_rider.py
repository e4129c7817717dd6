"""Render a rider mesh (vertex-coloured .ply from `python -m splatting rider --out`).

    python blender_scripts/render_rider.py --mesh RIDER.ply --out DIR [--views 0,1,2]
        the rest-pose rider from the 36-view ring into DIR (SHERF layout, resumable)
    python blender_scripts/render_rider.py --mesh POSED.ply --camera cameras.json:camera0007 --out FILE.png
        one posed mesh from one camera (FILE.png RGBA, FILE_mask.png, FILE_rgb.jpg)
    python blender_scripts/render_rider.py --batch JOBS.json
        many stills in one Blender session: [{"mesh", "camera", "out", "light_yaw_deg"}, ...]

Also runs as `blender -b -P blender_scripts/render_rider.py -- ARGS`.
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import UserError, run_main  # noqa: E402


def parse(argv):
    p = argparse.ArgumentParser(prog="render_rider.py", description=__doc__.splitlines()[0])
    p.add_argument("--mesh", help="rider .ply (canonical frame, vertex colours) or an imported rider.npz (with its textures)")
    p.add_argument("--out", help="views folder (ring mode) or output .png (with --camera)")
    p.add_argument("--camera", help="cameras.json:cameraNNNN, or a JSON file with one K/R/T: render one still")
    p.add_argument("--batch", help="JSON list of stills {mesh, camera, out, light_yaw_deg}")
    p.add_argument("--views", default=None, help="comma list of ring view indices (default: all 36)")
    p.add_argument("--light-yaw-deg", type=float, default=0.0,
                   help="turn the sun lights about the vertical by this angle (stills; match a global body yaw)")
    p.add_argument("--samples", type=int, default=None, help="Cycles samples (default: benchmarked setting)")
    p.add_argument("--denoise", choices=["NONE", "FAST", "BALANCED", "HIGH"], default=None)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--size", type=int, default=None, help="ring views: pixels a side (default 512; the cameras keep "
                                                          "their field of view)")
    args = p.parse_args(argv)
    if not args.batch and not (args.mesh and args.out):
        p.error("give --mesh and --out, or --batch")
    return args


def _views(text):
    if text is None:
        return None
    try:
        v = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--views wants comma-separated integers, got '{text}'")
    bad = [i for i in v if not 0 <= i < 36]
    if bad:
        raise UserError(f"--views: {bad[0]} is not a ring view (0-35)")
    return v


def main(argv):
    args = parse(argv)
    from cyclist_formats import checks
    checks.count("samples", args.samples, hi=1 << 16)
    checks.threads("threads", args.threads)
    checks.image_size("size", args.size)
    checks.finite("light_yaw_deg", args.light_yaw_deg)
    if args.batch:
        checks.input_file("batch", args.batch)
    else:
        checks.input_file("mesh", args.mesh)
        if args.camera:
            checks.output_file("out", args.out, (".png",))
        else:
            checks.output_dir("out", args.out)
    from dataclasses import replace

    from addon.core.render import render
    from addon.core.rider import rider_import

    s = replace(render.RenderSettings(), threads=args.threads)
    if args.samples:
        s = replace(s, samples=args.samples)
    if args.denoise:
        s = replace(s, denoise=args.denoise)
    if args.size:
        s = replace(s, size=args.size)
    if args.batch:
        try:
            with open(args.batch) as f:
                jobs = json.load(f)
        except (OSError, json.JSONDecodeError) as e:
            raise UserError(f"cannot read --batch {args.batch}: {e}")
        for i, job in enumerate(jobs):
            if os.path.isfile(job["out"]):
                continue  # resumable: the RGBA is renamed into place last
            rider_import.render_rider_still(job["mesh"], job["camera"], job["out"], s,
                                            float(job.get("light_yaw_deg", 0.0)))
            print(f"rider still {i + 1}/{len(jobs)}: {job['out']}", flush=True)
        return 0
    if not os.path.isfile(args.mesh):
        raise UserError(f"no rider mesh: {args.mesh}")
    if args.camera:
        rider_import.render_rider_still(args.mesh, args.camera, args.out, s, args.light_yaw_deg)
        return 0
    res = rider_import.render_rider_views(args.mesh, args.out, views=_views(args.views), settings=s)
    print(f"{args.out}: {res['rendered']} views rendered, {res['skipped']} already done")
    return 0


if __name__ == "__main__":
    run_main(main, "render_rider.py")

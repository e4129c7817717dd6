"""Render a bike's parts (and the whole bike) from the 36-view ring.

    blender -b -P blender_scripts/render_views.py -- --bike OUT/bikes/ID [--parts all]
    python blender_scripts/render_views.py --bike OUT/bikes/ID [--parts frame,steering]

Writes OUT/bikes/ID/views/<part>/ in the layout of docs/contract.md; reruns skip finished views.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import run_main  # noqa: E402


def parse(argv):
    p = argparse.ArgumentParser(prog="render_views.py", description=__doc__.splitlines()[0])
    p.add_argument("--bike", required=True, help="bike folder (holds bike.blend, keypoints.json)")
    p.add_argument("--parts", default="all", help="comma list of frame,steering,crank,front_wheel,rear_wheel,pedal_left,pedal_right,whole or 'all'")
    p.add_argument("--views", default=None, help="comma list of ring view indices (default: all 36)")
    p.add_argument("--samples", type=int, default=None, help="Cycles samples (default 128: measured in docs/training.md)")
    p.add_argument("--denoise", choices=["NONE", "FAST", "BALANCED", "HIGH"], default=None)
    p.add_argument("--adaptive-threshold", type=float, default=None,
                   help="Cycles adaptive-sampling noise threshold (default 0.05; 0: off, every pixel gets every sample)")
    p.add_argument("--size", type=int, default=None, help="image size in pixels (default 512; focal scales with it)")
    p.add_argument("--threads", type=int, default=2)
    return p.parse_args(argv)


def main(argv):
    args = parse(argv)
    from cyclist_formats import checks
    checks.input_dir("bike", args.bike)
    checks.count("samples", args.samples, hi=1 << 16)
    checks.image_size("size", args.size)
    checks.number("adaptive_threshold", args.adaptive_threshold, lo=0, hi=1)
    checks.threads("threads", args.threads)
    from addon.core.render import render_views

    render_views.render_bike(args.bike, parts=args.parts, views=args.views, samples=args.samples,
                             denoise=args.denoise, size=args.size, threads=args.threads,
                             adaptive_threshold=args.adaptive_threshold)
    return 0


if __name__ == "__main__":
    run_main(main, "render_views.py")

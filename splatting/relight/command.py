"""`python -m splatting relight-fit --views OUT/bikes/ID/views/PART | --bike OUT/bikes/ID`: per-Gaussian
albedo, gloss and normal fitted to the render passes (splatting/relight/fit.py)."""
import argparse
import os

from cyclist_formats.errors import UserError
from splatting.relight import fit


def add_arguments(p):
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--views", help="a part's views folder with albedo/ and normal/ passes")
    what.add_argument("--bike", help="a trained bike folder: fit every part on its views (views/PART), e.g. "
                                     "after bike-posed-train")
    p.add_argument("--ply", help="with --views: the trained Gaussians (default OUT/bikes/ID/gaussians/PART.ply)")
    p.add_argument("--iterations", type=int, help=f"optimisation steps (default {fit.BIKE_ITERATIONS} with --bike, "
                                                  f"{fit.RelightFitConfig.iterations} with --views)")
    p.add_argument("--max-size", type=int, default=fit.RelightFitConfig.max_size,
                   help="fit at most at this image size in px (default %(default)s)")
    p.add_argument("--relit-loss", type=float,
                   help=f"weight of the relit loss (display colours under random suns, a bike's materials; 0: off; "
                        f"default {fit.BIKE_RELIT_LOSS:g} with --bike, {fit.RelightFitConfig.relit_loss:g} with --views)")
    p.add_argument("--view-normals", action=argparse.BooleanOptionalAction, default=None,
                   help="view-dependent normals, normalize(n + B v) per Gaussian (default on with --bike, "
                        "off with --views)")
    p.add_argument("--quiet", action="store_true", help="no progress line")


def run(args):
    if args.iterations is not None and args.iterations < 1:
        raise UserError("--iterations must be >= 1")
    if args.max_size < 16:
        raise UserError("--max-size must be >= 16")
    if args.relit_loss is not None and not args.relit_loss >= 0:
        raise UserError("--relit-loss must be >= 0")
    base = fit.bike_fit_config() if args.bike else fit.RelightFitConfig()  # a bike's parts, or one part / an avatar
    cfg = fit.RelightFitConfig(iterations=args.iterations if args.iterations is not None else base.iterations,
                               max_size=args.max_size, progress=not args.quiet,
                               relit_loss=args.relit_loss if args.relit_loss is not None else base.relit_loss,
                               view_normals=args.view_normals if args.view_normals is not None else base.view_normals)
    if args.bike:
        if args.ply:
            raise UserError("--ply goes with --views, not --bike")
        if not os.path.isdir(args.bike):
            raise UserError(f"bike folder not found: {args.bike}")
        fit.fit_bike(args.bike, cfg)
        return 0
    if not os.path.isdir(args.views):
        raise UserError(f"views folder not found: {args.views}")
    print(fit.fit_summary(fit.fit_file(args.views, args.ply, cfg)))
    return 0

"""`python -m splatting relight-fit --views OUT/bikes/ID/views/PART | --bike OUT/bikes/ID`: per-Gaussian
albedo, gloss and normal fitted to the render passes (splatting/relight/fit.py)."""
import os

from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import add_model_arguments, model_from_args, options_of, record_of
from splatting.relight import fit

OPTIONS = options_of(fit.RelightFitConfig)  # iterations, max_size, relit_loss, view_normals


def add_arguments(p):
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--views", help="a part's views folder with albedo/ and normal/ passes")
    what.add_argument("--bike", help="a trained bike folder: fit every part on its views (views/PART), e.g. "
                                     "after bike-posed-train")
    p.add_argument("--ply", help="with --views: the trained Gaussians (default OUT/bikes/ID/gaussians/PART.ply)")
    bike, views = record_of(fit.bike_fit_config()), record_of(fit.RelightFitConfig())

    def defaults(path, _):  # a bike's parts fit with other defaults than one part or an avatar
        b, v = _shown(bike[path]), _shown(views[path])
        return f" (default {b})" if b == v else f" (default {b} with --bike, {v} with --views)"
    add_model_arguments(p, fit.RelightFitConfig, OPTIONS, defaults)
    p.add_argument("--quiet", action="store_true", help="no progress line")


def _shown(v):
    return {True: "on", False: "off"}.get(v, v) if isinstance(v, bool) else f"{v:g}" if isinstance(v, float) else str(v)


def run(args):
    base = fit.bike_fit_config() if args.bike else fit.RelightFitConfig()  # a bike's parts, or one part / an avatar
    cfg = model_from_args(fit.RelightFitConfig, args, OPTIONS, base=base, progress=not args.quiet)
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

"""`python -m splatting train --views OUT/bikes/ID/views/PART [--out FILE.ply]`: fit one part's Gaussians.

The options are derived from TrainConfig (and its DensifyConfig) by cyclist_formats.typed_config's
builder: every field whose metadata has a "help" becomes `--field-name` with the field's default,
type and choices, so the defaults have one source of truth.  The training itself is splatting.training.trainer.train.
"""
from cyclist_formats import checks
from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import add_dataclass_arguments, dataclass_from_args

from splatting.training.trainer import TrainConfig, default_out, train


def add_arguments(p):
    p.add_argument("--views", required=True, help="a part's views folder: OUT/bikes/ID/views/PART")
    p.add_argument("--out", help="output .ply (default OUT/bikes/ID/gaussians/PART.ply; metrics in PART.json beside it)")
    add_dataclass_arguments(p, TrainConfig())
    p.add_argument("--no-early-stop", action="store_true", help="run all iterations")
    p.add_argument("--quiet", action="store_true", help="no progress line")


def config_from_args(args):
    """The TrainConfig of the command line; impossible numbers are refused here, one line each
    (cyclist_formats.checks), for the command and for library callers alike."""
    checks.count("iterations", args.iterations)
    checks.positive("time_budget_s", args.time_budget_s)
    checks.gaussians("max_gaussians", args.densify_max_gaussians)
    checks.threads("threads", args.threads)
    checks.integer("seed", args.seed, 0)
    checks.positive("eps2d", args.eps2d, 10.0)
    cfg = dataclass_from_args(args, TrainConfig(), progress=not args.quiet)
    if any(i < 0 for i in cfg.holdout):
        raise UserError(f"--holdout view indices must be >= 0, got {args.holdout!r}")
    if args.no_early_stop:
        cfg.patience = 10 ** 9
    return cfg


def check_args(args):
    """Impossible values and unusable paths, refused before any work."""
    config_from_args(args)
    checks.views_folder(args.views)
    checks.output_file("out", args.out if args.out else default_out(args.views), (".ply",))


def run(args):
    cfg = config_from_args(args)
    m = train(args.views, args.out, cfg)
    out = args.out or default_out(args.views)
    print(f"{out}: {m['gaussians']} Gaussians, held-out PSNR {m['psnr']} dB, SSIM {m['ssim']}, "
          f"{m['iterations']} iterations in {m['wall_s']} s ({m['stopped']})")
    return 0

"""`python -m splatting train --views OUT/bikes/ID/views/PART [--out FILE.ply]`: fit one part's Gaussians.

The options are derived from TrainConfig (and its DensifyConfig) by cyclist_formats.typed_config's
builder: every field with a description becomes `--field-name` (a nested block's field is named
after itself: --max-gaussians), typed, ranged and with its choices and default from the field
declaration, so the defaults have one source of truth and a bad value is the field's one line.
The training itself is splatting.training.trainer.train.
"""
from cyclist_formats import checks
from cyclist_formats.typed_config import add_model_arguments, model_from_args, options_of

from splatting.training.config import TrainConfig

OPTIONS = options_of(TrainConfig)  # ("iterations", ..., "densify.max_gaussians")


def add_arguments(p):
    p.add_argument("--views", required=True, help="a part's views folder: OUT/bikes/ID/views/PART")
    p.add_argument("--out", help="output .ply (default OUT/bikes/ID/gaussians/PART.ply; metrics in PART.json beside it)")
    add_model_arguments(p, TrainConfig, OPTIONS, " (default {default})")
    p.add_argument("--no-early-stop", action="store_true", help="run all iterations")
    p.add_argument("--quiet", action="store_true", help="no progress line")


def config_from_args(args):
    """The TrainConfig of the command line; impossible values are refused here, one line naming the
    flag (the model's field declarations), for the command and for library callers alike."""
    extra = {"patience": 10 ** 9} if args.no_early_stop else {}
    return model_from_args(TrainConfig, args, OPTIONS, progress=not args.quiet, **extra)


def check_args(args):
    """Impossible values and unusable paths, refused before any work."""
    from splatting.training.trainer import default_out  # the training code: not for --help (training/config.py)

    config_from_args(args)
    checks.views_folder(args.views)
    checks.output_file("out", args.out if args.out else default_out(args.views), (".ply",))


def run(args):
    from splatting.training.trainer import default_out, train

    cfg = config_from_args(args)
    m = train(args.views, args.out, cfg)
    out = args.out or default_out(args.views)
    print(f"{out}: {m['gaussians']} Gaussians, held-out PSNR {m['psnr']} dB, SSIM {m['ssim']}, "
          f"{m['iterations']} iterations in {m['wall_s']} s ({m['stopped']})")
    return 0

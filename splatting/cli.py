"""`python -m splatting COMMAND ...`: one subcommand per pipeline stage.

Each command lives in its own module exposing `add_arguments(parser)` and `run(args)`;
modules are imported only when their command is used, so `--help` stays fast.
"""
import argparse
import importlib
import importlib.util
import sys

from cyclist_formats.errors import UserError

# name -> (module, one-line help)
COMMANDS = {
    "demo": ("splatting.demo", "the whole pipeline from nothing on a reduced budget, with a report"),
    "train": ("splatting.training.command", "train one part's Gaussians on its 36 rendered views"),
    "pose-bike": ("splatting.bike.command", "re-pose a bike's part Gaussians with the 8-DoF pose"),
    "bike-posed-train": ("splatting.bike.posed_train", "fine-tune a bike's part Gaussians together on renders of the posed bike"),
    "contact-sheet": ("splatting.bike.contact_sheet", "one view of every bike in a library on one PNG"),
    "rider": ("splatting.rider.command", "list the rider roster; export a rider mesh (rest or posed)"),
    "rider-avatar": ("splatting.rider.avatar_build", "build a rider's Gaussian avatar (render, train, skin)"),
    "rider-posed-train": ("splatting.rider.posed_train", "train an avatar's Gaussians through its skinning on posed renders"),
    "cyclist": ("splatting.cyclist.command", "pose, fit and render a rider on a bike over a sequence of frames"),
    "dataset": ("splatting.dataset.command", "COCO training images + annotations from a YAML config or preset"),
    "relight-fit": ("splatting.relight.fit", "fit per-Gaussian albedo and normal of trained Gaussians to the render passes"),
    # two-word commands: `python -m splatting dataset merge ...`
    "rider import": ("splatting.rider.import_command", "a rigged human (.glb/.fbx, Mixamo/Rigify bones) becomes a "
                                                        "roster rider (bones -> 24 SMPL joints, weights, textures)"),
    "dataset merge": ("splatting.dataset.merge", "merge a dataset's per-sample shards into annotations.json (idempotent)"),
    "library build": ("splatting.library.command", "build every bike's views + part Gaussians + posed fine-tune + ground-truth check "
                                                   "and every rider's avatar, resumable, into library.json"),
}


class OneLineParser(argparse.ArgumentParser):
    """Usage errors as one stderr line (the usage text is in --help), like every other bad input."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _available():
    return {k: v for k, v in COMMANDS.items() if importlib.util.find_spec(v[0]) is not None}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    cmds = _available()
    top = OneLineParser(prog="python -m splatting", description=__doc__.splitlines()[0])
    sub = top.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, helptext) in cmds.items():
        sub.add_parser(name, help=helptext, add_help=False)
    if argv[:2] and " ".join(argv[:2]) in cmds:
        name, rest = " ".join(argv[:2]), argv[2:]
    elif not argv or argv[0] not in cmds:
        top.parse_args(argv or ["--help"])  # prints help / usage error and exits
        return 2
    else:
        name, rest = argv[0], argv[1:]
    module = importlib.import_module(cmds[name][0])
    parser = OneLineParser(prog=f"python -m splatting {name}", description=cmds[name][1])
    module.add_arguments(parser)
    args = parser.parse_args(rest)
    try:
        if hasattr(module, "check_args"):  # impossible values, unusable paths: refused before any work
            module.check_args(args)
        return module.run(args) or 0
    except UserError as e:
        sys.stderr.write(f"splatting {name}: error: {e}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write(f"splatting {name}: interrupted\n")
        return 130

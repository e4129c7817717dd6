"""`python -m splatting COMMAND ...` (installed: `articcyclists COMMAND ...`): the whole pipeline.

Every command lives in its stage's command module (splatting/<stage>/command.py): the stage's own
command as the module's `add_arguments(parser)`, `check_args(args)` (optional) and `run(args)`, a
further command of the stage as a class of the module holding the same three functions (or
`main(argv)` where the implementation module still parses its own arguments); the Blender stages
(blender_scripts/) run through splatting/blender/command.py.  Modules are imported only when their
command is used, so `--help` stays fast.
"""
import argparse
import importlib
import importlib.util
import sys

from cyclist_formats.errors import UserError
from splatting.blender.command import STAGES as BLENDER_STAGES, list_stages

# name -> ("module" or "module:Class", one-line help)
COMMANDS = {
    "demo": ("splatting.demo", "the whole pipeline from nothing on a reduced budget, with a report"),
    "train": ("splatting.training.command", "train one part's Gaussians on its 36 rendered views"),
    "pose-bike": ("splatting.bike.command", "re-pose a bike's part Gaussians with the 8-DoF pose"),
    "bike-posed-train": ("splatting.bike.command:PosedTrain", "fine-tune a bike's part Gaussians together on renders of the posed bike"),
    "contact-sheet": ("splatting.bike.command:ContactSheet", "one view of every bike in a library on one PNG"),
    "rider": ("splatting.rider.command", "list the rider roster; export a rider mesh (rest or posed)"),
    "rider-avatar": ("splatting.rider.command:Avatar", "build a rider's Gaussian avatar (render, train, skin)"),
    "rider-posed-train": ("splatting.rider.command:PosedTrain", "train an avatar's Gaussians through its skinning on posed renders"),
    "cyclist": ("splatting.cyclist.command", "pose, fit and render a rider on a bike over a sequence of frames"),
    "dataset": ("splatting.dataset.command", "COCO training images + annotations from a YAML config or preset"),
    "relight-fit": ("splatting.relight.command", "fit per-Gaussian albedo and normal of trained Gaussians to the render passes"),
    # two-word commands: `python -m splatting dataset merge ...`
    "rider import": ("splatting.rider.import_command", "a rigged human (.glb/.fbx, Mixamo/Rigify bones) becomes a "
                                                        "roster rider (bones -> 24 SMPL joints, weights, textures)"),
    "dataset merge": ("splatting.dataset.command:Merge", "merge a dataset's per-sample shards into annotations.json (idempotent)"),
    "dataset looks-sheet": ("splatting.dataset.command:LooksSheet", "one cyclist in N sampled looks (appearance variety) on one PNG"),
    "dataset frames-sheet": ("splatting.dataset.command:FramesSheet", "a frames-mode (KITTI insert) dataset's samples with their labels on one PNG"),
    "dataset strip": ("splatting.dataset.command:SequenceStrip", "a sequence dataset's frames with track boxes, ids and trails on one PNG"),
    "library build": ("splatting.library.command", "build every bike's views + part Gaussians + posed fine-tune + ground-truth check "
                                                   "and every rider's avatar, resumable, into library.json"),
}
# the Blender stages: `python -m splatting blender render-views [--blender PATH] -- ARGS`
COMMANDS.update({f"blender {name}": ("splatting.blender.command", stage.help) for name, stage in BLENDER_STAGES.items()})


class OneLineParser(argparse.ArgumentParser):
    """Usage errors as one stderr line (the usage text is in --help), like every other bad input."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _available():
    """The commands whose module is there (an installed copy may lack an optional stage)."""
    return {k: v for k, v in COMMANDS.items() if importlib.util.find_spec(v[0].split(":")[0]) is not None}


def load(target):
    """The command object of a COMMANDS entry: the module itself, or the class named after ':'."""
    module, _, attr = target.partition(":")
    module = importlib.import_module(module)
    return getattr(module, attr) if attr else module


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    cmds = _available()
    top = OneLineParser(prog="python -m splatting", description=__doc__.splitlines()[0])
    sub = top.add_subparsers(dest="command", metavar="COMMAND")
    for name, (_, helptext) in cmds.items():
        sub.add_parser(name, help=helptext, add_help=False)
    if argv[:2] and " ".join(argv[:2]) in cmds:
        name, rest = " ".join(argv[:2]), argv[2:]
    elif argv and argv[0] == "blender":  # `blender`, `blender --help`: the stages; `blender nosuch`: one line
        return list_stages(argv[1:])
    elif not argv or argv[0] not in cmds:
        top.parse_args(argv or ["--help"])  # prints help / usage error and exits
        return 2
    else:
        name, rest = argv[0], argv[1:]
    if name.startswith("blender "):  # a Blender stage: its script parses its own arguments
        return BLENDER_STAGES[name.split(" ", 1)[1]].main(rest)
    command = load(cmds[name][0])
    if not hasattr(command, "main"):  # a module that parses its own arguments is handed them as they are
        parser = OneLineParser(prog=f"python -m splatting {name}", description=cmds[name][1])
        command.add_arguments(parser)
        args = parser.parse_args(rest)
    try:
        if hasattr(command, "main"):
            return command.main(rest) or 0
        if hasattr(command, "check_args"):  # impossible values, unusable paths: refused before any work
            command.check_args(args)
        return command.run(args) or 0
    except UserError as e:
        sys.stderr.write(f"splatting {name}: error: {e}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write(f"splatting {name}: interrupted\n")
        return 130

"""`python -m splatting pose-bike`: re-pose a bike's part Gaussians with the 8-DoF pose; the bike stage's
other commands, `bike-posed-train` and `contact-sheet`, are the classes at the end.

One pose:  --pose "p,s,X,Y,Z,tx,ty,tz" --out FILE.ply [--keypoints-out FILE.json]
A batch:   --poses FILE.json --out DIR  ->  DIR/pose_%05d.ply + DIR/pose_%05d.json (keypoints)
Angles in degrees, translations in metres (docs/contract.md).  A pose starting with '-' must be
written --pose=-10,0,... so that argparse does not read it as an option.
"""
import json
import os
import sys

from cyclist_formats import checks
from cyclist_formats.atomic import write_json
from cyclist_formats.errors import UserError

from cyclist_formats.typed_config import add_model_arguments, model_from_args, options_of
from cyclist_formats.pose import FIELDS_HELP  # numpy only: --help does not import torch

# The stage's modules are imported inside the functions below, not at the top: they load torch
# (~2.5 s, python -X importtime), and `--help` and the argument checks answer before that (0.2-0.5 s).

BATCH_CHUNK = 8  # poses posed at once in --poses mode (bounds memory: ~22 MB per pose at 100k, SH 3)


def add_arguments(p):
    p.add_argument("--bike", required=True, help="bike folder OUT/bikes/ID (gaussians/<part>.ply, keypoints.json, meta.json)")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--pose", help="one pose 'p,s,X,Y,Z,tx,ty,tz': " + FIELDS_HELP)
    g.add_argument("--poses", help="JSON file: a list of 8-lists or of dicts with " + FIELDS_HELP)
    p.add_argument("--out", required=True, help="output .ply (with --pose) or folder (with --poses)")
    p.add_argument("--keypoints-out", help="with --pose: also write the posed keypoints to this JSON file")
    p.add_argument("--bike-id", help="fail unless the bike's meta.json bike_id is this")
    p.add_argument("--sh-degree", type=int, choices=(0, 1, 2, 3), help="truncate SH to this degree (default: the file's)")


def keypoints_doc(model, pose, keypoints):
    from splatting.bike.pose import pose_dict

    return {"frame": "world", "units": "m", "bike_id": model.bike_id, "pose": pose_dict(pose),
            "keypoints": {k: [float(x) for x in v.tolist()] for k, v in keypoints.items()}}


def check_args(args):
    checks.input_dir("bike", args.bike)
    if args.pose is not None:
        checks.output_file("out", args.out, (".ply",))
        checks.output_file("keypoints_out", args.keypoints_out, (".json",))
    else:
        checks.output_dir("out", args.out)


def run(args):
    from splatting.bike.pose import parse_pose_string, poses_from_json
    from splatting.gaussians.container import write_ply

    # validate every input before loading or writing anything
    if args.pose is not None:
        poses = parse_pose_string(args.pose)[None]
        if os.path.isdir(args.out):
            raise UserError(f"--out {args.out} is a folder; with --pose give a .ply file")
    else:
        if args.keypoints_out:
            raise UserError("--keypoints-out goes with --pose; with --poses keypoints go to --out/pose_%05d.json")
        try:
            with open(args.poses) as f:
                poses = poses_from_json(json.load(f))
        except FileNotFoundError:
            raise UserError(f"no poses file: {args.poses}")
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise UserError(f"{args.poses} is not valid JSON: {e}")
        if os.path.exists(args.out) and not os.path.isdir(args.out):
            raise UserError(f"--out {args.out} exists and is not a folder")

    from splatting.bike.model import BikeModel  # torch import only after the arguments are known good

    model = BikeModel.load(args.bike, bike_id=args.bike_id, sh_degree=args.sh_degree)
    if args.pose is not None:
        posed = model.pose(poses[0])
        write_ply(posed.gaussians, args.out)
        if args.keypoints_out:
            write_json(args.keypoints_out, keypoints_doc(model, poses[0], posed.keypoints))
        sys.stderr.write(f"pose-bike: {len(posed.gaussians)} Gaussians -> {args.out}\n")
        return 0

    from splatting.bike.model import posed_from_tensors

    os.makedirs(args.out, exist_ok=True)
    n, prev = poses.shape[0], None
    for start in range(0, n, BATCH_CHUNK):
        chunk = poses[start:start + BATCH_CHUNK]
        # each chunk is written out before the next is posed, so its buffers can be reused
        out = model.pose_tensors(chunk, reuse=prev if prev is not None and len(chunk) == len(prev["poses"]) else None)
        for j in range(len(chunk)):
            posed = posed_from_tensors(out, j)
            i = start + j
            write_ply(posed.gaussians, os.path.join(args.out, f"pose_{i:05d}.ply"))
            write_json(os.path.join(args.out, f"pose_{i:05d}.json"), keypoints_doc(model, chunk[j], posed.keypoints))
        prev = out
        sys.stderr.write(f"pose-bike: {min(start + BATCH_CHUNK, n)}/{n} poses\n")
    return 0


class PosedTrain:
    """`python -m splatting bike-posed-train --bike OUT/bikes/ID`: the parts fine-tuned together on
    renders of the posed bike (splatting/bike/posed_train.py)."""

    @staticmethod
    def add_arguments(p):
        from splatting.bike.posed_config import PosedTrainConfig

        p.add_argument("--bike", required=True, help="a bike folder with trained parts (gaussians/) and views/whole")
        p.add_argument("--from-rest", action="store_true",
                       help="start from gaussians/<part>_rest.ply as they are and never write them (the layout "
                            "`library build` leaves; default: keep the current <part>.ply as <part>_rest.ply first)")
        add_model_arguments(p, PosedTrainConfig, options_of(PosedTrainConfig), " (default {default})")  # --poses ... --eps2d
        p.add_argument("--render-threads", type=int,
                       help="Blender's CPU threads for the posed renders (default: its own, 2); the fine-tune uses one")
        p.add_argument("--quiet", action="store_true", help="no progress line")

    @staticmethod
    def check_args(args):
        checks.input_dir("bike", args.bike)
        PosedTrain.config_from_args(args)  # the values, one line naming the flag (the model's ranges)
        if args.render_threads is not None:
            checks.threads("render-threads", args.render_threads)
        for p in ("frame", "steering"):
            f = p + ("_rest.ply" if args.from_rest else ".ply")
            if not os.path.isfile(os.path.join(args.bike, "gaussians", f)):
                raise UserError(f"{args.bike} has no trained gaussians/{f} (python -m splatting train first)")

    @staticmethod
    def config_from_args(args):
        """The PosedTrainConfig of a parsed command line; a bad value is a UserError naming its flag."""
        from splatting.bike.posed_config import PosedTrainConfig

        return model_from_args(PosedTrainConfig, args, options_of(PosedTrainConfig), progress=not args.quiet)

    @staticmethod
    def run(args):
        from splatting.bike.posed_train import train_bike_posed

        train_bike_posed(args.bike, PosedTrain.config_from_args(args), from_rest=args.from_rest,
                         render_threads=args.render_threads)
        return 0


class ContactSheet:
    """`python -m splatting contact-sheet --bikes OUT/bikes --out FILE.png` (splatting/bike/contact_sheet.py)."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("--bikes", required=True, help="folder holding <bike_id>/views/whole/")
        p.add_argument("--out", required=True, help="output PNG")
        p.add_argument("--view", type=int, default=3, help="ring view index to show (default 3: front-left three-quarter)")
        p.add_argument("--cols", type=int, default=6)
        p.add_argument("--tile", type=int, default=256, help="tile size in pixels")

    @staticmethod
    def check_args(args):
        checks.input_dir("bikes", args.bikes)
        checks.index("view", args.view, 36)
        checks.integer("cols", args.cols, 1, 1000)
        checks.image_size("tile", args.tile)
        checks.output_file("out", args.out, (".png",))

    @staticmethod
    def run(args):
        from splatting.bike.contact_sheet import contact_sheet

        n = contact_sheet(args.bikes, args.out, args.view, args.cols, args.tile)
        print(f"contact sheet of {n} bikes -> {args.out}")

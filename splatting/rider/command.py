"""`python -m splatting rider`: list the roster, export a rider's mesh (rest or posed); the rider stage's
other commands, `rider-avatar` and `rider-posed-train`, are the classes at the end (`rider import`:
import_command.py)."""
import math
import os

import torch

from cyclist_formats import checks
from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import add_model_arguments, model_from_args, options_of
from splatting.training.config import TrainConfig

# The stage's modules are imported inside the functions below, not at the top: they load torch
# (~2.5 s, python -X importtime), and `--help` and the argument checks answer before that (0.2-0.5 s).


def add_arguments(p):
    p.add_argument("--list", action="store_true", help="print the roster (with the imported riders), one rider a line, id first")
    p.add_argument("--id", help="rider id (see --list)")
    p.add_argument("--out", help="mesh file to write (.ply or .obj, vertex colours, canonical frame)")
    p.add_argument("--theta-p-deg", type=float, help="pose with the built-in pedalling motion at this crank angle")
    p.add_argument("--theta-s-deg", type=float, default=0.0, help="steering angle for the built-in pose")
    p.add_argument("--motion", help="CLIFF or AMASS .npz: pose the rider with one of its frames")
    p.add_argument("--frame", type=int, default=0, help="frame of --motion (default 0)")


def check_args(args):
    checks.finite("theta_p_deg", args.theta_p_deg)
    checks.finite("theta_s_deg", args.theta_s_deg)
    checks.integer("frame", args.frame, 0)
    if args.motion is not None:
        checks.input_file("motion", args.motion)
    checks.output_file("out", args.out, (".ply", ".obj"))


def run(args):
    from splatting.rider.roster import all_riders, describe
    if args.list:
        for r in all_riders():
            print(describe(r))
        return 0
    if not args.id or not args.out:
        raise UserError("give --list, or --id ID --out FILE.ply|.obj")
    if not args.out.lower().endswith((".ply", ".obj")):
        raise UserError(f"--out must end in .ply or .obj, got {args.out}")
    for name in ("theta_p_deg", "theta_s_deg"):
        v = getattr(args, name)
        if v is not None and not math.isfinite(v):
            raise UserError(f"--{name.replace('_', '-')} must be a finite number")
    from splatting.rider.body import export_rider, pose_vertices
    from splatting.rider.roster import load_rider
    torch.set_num_threads(max(1, min(2, torch.get_num_threads())))
    rider = load_rider(args.id)
    verts = None
    if args.motion:
        from splatting.rider.motion import load_motion
        m = load_motion(args.motion)
        if not 0 <= args.frame < len(m):
            raise UserError(f"--frame {args.frame} out of range (motion has {len(m)} frames)")
        f = slice(args.frame, args.frame + 1)
        verts = pose_vertices(rider, m.local_rotmats[f], m.root_trans(rider)[f])[0]
    elif args.theta_p_deg is not None:
        from splatting.rider.motion import pedal_pose
        rot, root, _ = pedal_pose(rider.joints, math.radians(args.theta_p_deg),
                                  math.radians(args.theta_s_deg))
        verts = pose_vertices(rider, rot, root)[0]
    export_rider(rider, args.out, verts)
    print(f"wrote {args.out} ({rider.vertices.shape[0]} vertices, rider {rider.id}, "
          f"{rider.height_m:.3f} m)")
    return 0

# the TrainConfig fields rider-avatar takes on its command line
AVATAR_TRAINING = ("iterations", "time_budget_s", "densify.max_gaussians", "threads")


class Avatar:
    """`python -m splatting rider-avatar --id ID [--out data/riders/ID]`: render, train and skin a rider's
    Gaussian avatar, resumable (splatting/rider/avatar_build.py)."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("--id", required=True, help="rider id from the roster (python -m splatting rider --list)")
        p.add_argument("--out", help="avatar folder (default data/riders/ID)")
        # the avatar's training: the trainer's own fields, flags and defaults (reduced budget: e.g. --iterations 1500)
        add_model_arguments(p, TrainConfig, AVATAR_TRAINING, " (default {default})")
        p.add_argument("--samples", type=int, default=None, help="Cycles samples for the 36 views")
        p.add_argument("--size", type=int, default=None, help="pixels a side of the 36 views (default 512)")
        p.add_argument("--bare", action="store_true", help="train the rider without helmet, hair or bag: the base "
                       "that datasets add per-instance accessories to (default --out data/riders/ID/bare)")

    @staticmethod
    def train_config(args):
        """The avatar's TrainConfig of the command line; a bad value is one line naming its flag."""
        return model_from_args(TrainConfig, args, AVATAR_TRAINING)

    @staticmethod
    def check_args(args):
        Avatar.train_config(args)
        checks.image_size("size", args.size)
        checks.count("samples", args.samples, hi=1 << 16)
        checks.output_dir("out", args.out)

    @staticmethod
    def run(args):
        from splatting import paths
        from splatting.rider.avatar import BARE_NAME
        from splatting.rider.avatar_build import build_avatar

        cfg = Avatar.train_config(args)
        out = args.out or os.path.join(paths.DATA, "riders", args.id, *([BARE_NAME] if args.bare else []))
        res = build_avatar(args.id, out, cfg.iterations, cfg.time_budget_s, cfg.densify.max_gaussians, args.samples,
                           cfg.threads, size=args.size, bare=args.bare)
        print(f"{out}: avatar ready ({', '.join(f'{k} {v}' for k, v in res['steps'].items())})")
        return 0


class PosedTrain:
    """`python -m splatting rider-posed-train --avatar DIR`: an avatar's Gaussians trained through its
    skinning on renders of the posed rider (splatting/rider/posed_train.py)."""

    @staticmethod
    def add_arguments(p):
        from splatting.rider.posed_config import PosedTrainConfig

        p.add_argument("--avatar", required=True, help="a rider avatar folder (rider.ply, skinning.npz, views/)")
        add_model_arguments(p, PosedTrainConfig, options_of(PosedTrainConfig), " (default {default})")
        p.add_argument("--quiet", action="store_true")

    @staticmethod
    def run(args):
        from splatting.rider.posed_config import PosedTrainConfig
        from splatting.rider.posed_train import train_avatar_posed

        cfg = model_from_args(PosedTrainConfig, args, options_of(PosedTrainConfig), progress=not args.quiet)
        if not os.path.isfile(os.path.join(args.avatar, "skinning.npz")):
            raise UserError(f"not a rider avatar folder (no skinning.npz): {args.avatar}")
        train_avatar_posed(args.avatar, cfg)
        return 0


"""`python -m splatting rider`: list the roster, export a rider's mesh (rest or posed)."""
import math

import torch

from cyclist_formats import checks
from cyclist_formats.errors import UserError

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

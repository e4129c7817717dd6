"""`python -m splatting cyclist --rider ID --bike BIKE --frames N --views 0,90,180,-90 --out DIR`.

Per frame: the bike's 8-DoF pose (theta_p, theta_s from a motion file or the pedalling programme,
a fixed global H_g), the rider IK onto the posed bike keypoints (one call for the whole sequence,
one shared seat post), the rider re-posed by LBS, rider + bike Gaussians concatenated and rendered
from every view.  Layout (docs/contract.md cyclist runs):
  DIR/frame_%05d.json                 pose, bike_keypoints, rider_joints, ik (written last: marks the frame done)
  DIR/view_<az>/%05d.png              RGBA (straight alpha)
  DIR/view_<az>/%05d_mask.png         instance ids: 0 background, frame 1, steering 2, crank 3, rider 4
  DIR/view_<az>/%05d_depth.png        uint16 depth along the camera axis in millimetres (0 = background)
  DIR/view_<az>/%05d_keypoints.json   2D bike keypoints and rider joints [u, v, visibility 0/1/2]
  DIR/view_<az>/cameras.json          SHERF layout + orbit_centre
  DIR/ply/%05d.ply                    the composed cyclist, INRIA layout (--ply)
  DIR/preview.png, DIR/preview.gif    a strip per view / the first view animated
"""
import math
import os

import torch

from cyclist_formats import bike_folder, checks
from cyclist_formats.errors import UserError
from splatting.cyclist.sequence import fit_sequence, motion_poses, programme_poses, render_sequence

# The stage's modules are imported inside the functions below, not at the top: they load torch
# (~2.5 s, python -X importtime), and `--help` and the argument checks answer before that (0.2-0.5 s).

def add_arguments(p):
    p.add_argument("--rider", help="roster rider id (`python -m splatting rider --list`)")
    p.add_argument("--bike", help="bike folder, or a bike id under --bikes-root")
    p.add_argument("--bikes-root", default="out/bikes")
    p.add_argument("--riders-root", default="data/riders", help="trained avatars live in RIDERS_ROOT/ID/")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--motion", help="CLIFF or AMASS .npz: theta_p, theta_s from the pose, IK starts from it")
    src.add_argument("--pedal-rpm", type=float, default=None, help="pedalling programme cadence (default 80)")
    p.add_argument("--steer-range", default="0,0", help="A,B degrees: steering swings between A and B once per sequence")
    p.add_argument("--fps", type=float, default=24.0, help="frame rate of the programme (default 24)")
    p.add_argument("--global-pose", default="0,0,0,0,0,0", help="theta_X,theta_Y,theta_Z (deg),t_X,t_Y,t_Z (m): H_g")
    p.add_argument("--frames", type=int, default=24)
    p.add_argument("--views", default="0,90,180,-90", help="ring azimuths in degrees")
    p.add_argument("--elevation", type=float, default=0.0, help="camera elevation in degrees (default 0: the ring)")
    p.add_argument("--distance", type=float, default=12.0, help="camera distance in metres (default 12: the ring)")
    p.add_argument("--size", type=int, default=512, help="image size (the ring focal length scales with it)")
    p.add_argument("--out", required=True)
    p.add_argument("--ply", action="store_true", help="also write the composed cyclist per frame as .ply")
    p.add_argument("--all-combinations", action="store_true",
                   help="every roster rider x every bike (with a crank) under --bikes-root, into OUT/<rider>__<bike>/")
    p.add_argument("--synthetic", choices=("auto", "always", "never"), default="auto",
                   help="stand-in Gaussians when trained ones are missing (auto), always, or never (error)")
    p.add_argument("--rider-gaussians", type=int, default=None, help="subsample an untrained (mesh) avatar")
    p.add_argument("--ik-iterations", type=int, default=50)
    p.add_argument("--kp-tolerance", default="0.08,0.15", help="bike,rider depth tolerance (m) of keypoint visibility")


def _floats(text, n, flag):
    try:
        v = [float(x) for x in str(text).split(",")]
    except ValueError:
        raise UserError(f"{flag} needs {n} comma-separated numbers, got {text!r}")
    if len(v) != n or not all(math.isfinite(x) for x in v):
        raise UserError(f"{flag} needs {n} finite comma-separated numbers, got {text!r}")
    return v


def parse_views(text):
    try:
        v = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--views must be comma-separated azimuths in degrees, got {text!r}")
    if not v or not all(math.isfinite(x) for x in v):
        raise UserError(f"--views must be finite azimuths, got {text!r}")
    return v


def run_one(args, rider_id, bike, out, log):
    from splatting.cyclist.assets import bike_dir, load_avatar, load_bike
    from splatting.cyclist.compose import Cyclist, check_rider_fits
    d = bike_dir(bike, args.bikes_root)
    model = load_bike(d, args.synthetic, log=log)
    avatar, rider = load_avatar(rider_id, args.riders_root, args.synthetic, args.rider_gaussians, log=log)
    cyc = Cyclist(model, avatar, args.ik_iterations)
    check_rider_fits(cyc)
    g = _floats(args.global_pose, 6, "--global-pose")
    steer = _floats(args.steer_range, 2, "--steer-range")
    motion_aa = None
    if args.motion:
        poses, motion_aa = motion_poses(args.motion, rider, model, args.frames, g)
    else:
        poses = programme_poses(args.frames, 80.0 if args.pedal_rpm is None else args.pedal_rpm, args.fps, steer, g)
    fit = fit_sequence(cyc, poses, motion_aa)
    meta = {"rider": rider_id, "bike": model.bike_id, "source": args.motion or "programme"}
    tol = _floats(args.kp_tolerance, 2, "--kp-tolerance")
    r = render_sequence(cyc, poses, parse_views(args.views), out, args.size, args.elevation, args.distance,
                        args.ply, fit, tol, meta, log)
    flagged = sum(bool(v.any()) for v in fit.flagged.values())
    log(f"cyclist: {rider_id} on {model.bike_id}: {r['frames']} frames x {len(parse_views(args.views))} views in {out} "
        f"({r['rendered']} rendered, {r['skipped']} resumed, {r['wall_s']:.1f} s); "
        f"worst IK residual {max(float(v.max()) for v in fit.residuals.values()) * 100:.1f} cm"
        + (f", {flagged} target pairs flagged" if flagged else ""))
    return r


def check_args(args):
    """Impossible values (a negative camera distance, an image beyond memory) and unusable paths."""
    checks.count("frames", args.frames, hi=1_000_000)
    checks.image_size("size", args.size)
    checks.positive("distance", args.distance, hi=1e4)
    checks.number("elevation", args.elevation, -90, 90, lo_open=True, hi_open=True)
    checks.positive("fps", args.fps, hi=10_000)
    checks.number("pedal_rpm", args.pedal_rpm, 0, 1000)
    checks.count("ik_iterations", args.ik_iterations, hi=100_000)
    checks.gaussians("rider_gaussians", args.rider_gaussians, lo=100)
    tol = _floats(args.kp_tolerance, 2, "--kp-tolerance")
    if min(tol) < 0:
        raise UserError(f"--kp-tolerance values must be >= 0, got {args.kp_tolerance!r}")
    if args.motion is not None:
        checks.input_file("motion", args.motion)
    checks.output_dir("out", args.out)


def run(args):
    if args.frames < 1:
        raise UserError("--frames must be >= 1")
    if args.size < 16:
        raise UserError("--size must be >= 16")
    if args.pedal_rpm is not None and not math.isfinite(args.pedal_rpm):
        raise UserError("--pedal-rpm must be finite")
    if not (args.fps > 0 and math.isfinite(args.fps)):
        raise UserError("--fps must be positive")
    parse_views(args.views)
    torch.set_num_threads(min(torch.get_num_threads(), 2))
    log = lambda m: print(m, flush=True)  # noqa: E731
    if not args.all_combinations:
        if not args.rider or not args.bike:
            raise UserError("--rider and --bike are required (or --all-combinations)")
        run_one(args, args.rider, args.bike, args.out, log)
        return 0
    from splatting.rider.roster import all_riders
    riders = [args.rider] if args.rider else [r["id"] for r in all_riders()]
    if args.bike:
        bikes = [args.bike]
    else:
        root = args.bikes_root
        if not os.path.isdir(root):
            raise UserError(f"no bikes root {root}")
        bikes = sorted(b for b in os.listdir(root) if os.path.isfile(os.path.join(root, b, "keypoints.json"))
                       and bike_folder.has_crank(os.path.join(root, b)))
    log(f"cyclist: {len(riders)} riders x {len(bikes)} bikes = {len(riders) * len(bikes)} combinations")
    for r in riders:
        for b in bikes:
            run_one(args, r, b, os.path.join(args.out, f"{r}__{os.path.basename(os.path.normpath(b))}"), log)
    return 0

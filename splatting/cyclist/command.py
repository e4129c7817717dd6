"""`python -m splatting cyclist --rider ID --bike BIKE --frames N --views 0,90,180,-90 --out DIR`.

Per frame: the bike's 8-DoF pose (theta_p, theta_s from a motion file or the pedalling programme,
a fixed global H_g), the rider IK onto the posed bike keypoints (one call for the whole sequence,
one shared seat post), the rider re-posed by LBS, rider + bike Gaussians concatenated and rendered
from every view.  Layout (DESIGN.md cyclist runs):
  DIR/frame_%05d.json                 pose, bike_keypoints, rider_joints, ik (written last: marks the frame done)
  DIR/view_<az>/%05d.png              RGBA (straight alpha)
  DIR/view_<az>/%05d_mask.png         instance ids: 0 background, frame 1, steering 2, crank 3, rider 4
  DIR/view_<az>/%05d_depth.png        uint16 depth along the camera axis in millimetres (0 = background)
  DIR/view_<az>/%05d_keypoints.json   2D bike keypoints and rider joints [u, v, visibility 0/1/2]
  DIR/view_<az>/cameras.json          SHERF layout + orbit_centre
  DIR/ply/%05d.ply                    the composed cyclist, INRIA layout (--ply)
  DIR/preview.png, DIR/preview.gif    a strip per view / the first view animated
"""
import json
import math
import os
import sys
import time

import numpy as np
import torch

from cyclist_formats.atomic import atomic_path, write_json
from cyclist_formats.errors import UserError

MAX_PREVIEW_COLUMNS = 8


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


def view_name(az):
    return f"view_{float(az):g}"  # view_0, view_90, view_-90, view_22.5


def programme_poses(n, rpm, fps, steer_range, global_pose):
    """(n, 8) poses: theta_p advancing at rpm, theta_s swinging once between A and B, fixed H_g."""
    f = torch.arange(n, dtype=torch.float64)
    tp = (360.0 * rpm / 60.0 / fps * f) % 360.0
    a, b = steer_range
    ts = 0.5 * (a + b) + 0.5 * (b - a) * torch.sin(2 * math.pi * f / max(n, 1))
    g = torch.tensor(global_pose, dtype=torch.float64).expand(n, 6)
    return torch.cat([tp[:, None], ts[:, None], g], 1)


def motion_poses(motion_path, rider, bike, n, global_pose):
    """theta_p, theta_s per frame from a motion file (theta_from_pose) + the motion's local rotations."""
    import roma
    from splatting.rider.body import posed_joints
    from splatting.rider.motion import load_motion, theta_from_pose
    m = load_motion(motion_path)
    if len(m) < n:
        raise UserError(f"{motion_path} has {len(m)} frames, --frames asks for {n}")
    rot = m.local_rotmats[:n].double()
    joints = posed_joints(rider, rot, m.root_trans(rider)[:n].double())
    tp, ts = theta_from_pose(joints, steer_axis=bike.steer_axis)
    g = torch.tensor(global_pose, dtype=torch.float64).expand(n, 6)
    poses = torch.cat([torch.rad2deg(tp)[:, None], torch.rad2deg(ts)[:, None], g], 1)
    return poses, roma.rotmat_to_rotvec(rot).float()


def fit_sequence(cyc, poses, motion_aa=None):
    """IK for all frames at once with one seat post.  With a motion: a second solve starts from the
    first one's solution with the motion's rotations on the joints the IK does not move."""
    from splatting.rider import ik
    res = cyc.fit_rider(poses, saddle_shared=True)
    if motion_aa is None:
        return res
    keep = [i for i, n in enumerate(ik.JOINT_INDEX) if n not in ik._SLOT_JOINTS]
    init = res.local_aa.clone()
    init[:, keep] = motion_aa[:, keep]
    p = poses.clone()
    p[:, 2:] = 0.0
    targets = ik.posed_bike_keypoints(cyc.bike.keypoints, p)
    return ik.solve(cyc.avatar.rest_joints, targets, init_local_aa=init, init_root=res.root_trans,
                    iterations=cyc.ik_iterations, saddle_fit=cyc.saddle_fit, saddle_shared=cyc.saddle_fit,
                    pairs=cyc.pairs)


def _save_png(path, arr):
    from PIL import Image
    with atomic_path(path) as tmp:
        Image.fromarray(arr).save(tmp, format="PNG")


def frame_done(out, i, views, ply):
    if not os.path.isfile(os.path.join(out, f"frame_{i:05d}.json")):
        return False
    files = [os.path.join(out, view_name(az), f"{i:05d}{s}") for az in views
             for s in (".png", "_mask.png", "_depth.png", "_keypoints.json")]
    if ply:
        files.append(os.path.join(out, "ply", f"{i:05d}.ply"))
    return all(os.path.isfile(f) for f in files)


def render_sequence(cyc, poses, views, out, size=512, elevation=0.0, distance=12.0, ply=False, fit=None,
                    tolerances=(0.08, 0.15), meta=None, log=print, chunk=8):
    """Render a posed sequence into `out` (layout: module docstring); frames already complete are
    skipped.  Returns {"frames", "rendered", "skipped", "wall_s"}."""
    from splatting.bike.model import KEYPOINTS
    from splatting.gaussians.container import write_ply
    from splatting.rider.kinematics import JOINT_NAMES
    from splatting.cyclist.compose import frame_record, take_fit
    from splatting.cyclist.render import keypoint_visibility, orbit_camera, project_points, render_layers, rgba_image

    n = poses.shape[0]
    os.makedirs(out, exist_ok=True)
    # one orbit centre for the whole sequence (DESIGN.md: (x, h, z) of the first frame's box centre)
    first = cyc.pose(poses[:1], fit=None if fit is None else take_fit(fit, slice(0, 1)))[0]
    lo, hi = first.gaussians.means.min(0).values, first.gaussians.means.max(0).values
    centre = (0.5 * (lo + hi)).double().tolist()
    cams = {az: orbit_camera(az, elevation, distance, centre, size, name=view_name(az)) for az in views}
    for az, cam in cams.items():
        write_json(os.path.join(out, view_name(az), "cameras.json"),
                   {"camera0000": {"K": cam.K.tolist(), "R": cam.R.tolist(), "T": cam.T.tolist()},
                    "orbit_centre": centre, "azimuth_deg": az, "elevation_deg": elevation, "distance_m": distance})
    todo = [i for i in range(n) if not frame_done(out, i, views, ply)]
    if len(todo) < n:
        log(f"cyclist: {n - len(todo)} of {n} frames already done in {out}")
    t0 = time.time()
    for c in range(0, len(todo), chunk):
        idx = todo[c:c + chunk]
        frames = cyc.pose(poses[idx], fit=None if fit is None else take_fit(fit, idx))
        for i, fr in zip(idx, frames):
            for az, cam in cams.items():
                d = os.path.join(out, view_name(az))
                L = render_layers(fr.gaussians, fr.ids, cam)
                _save_png(os.path.join(d, f"{i:05d}.png"), rgba_image(L))
                _save_png(os.path.join(d, f"{i:05d}_mask.png"), L["ids"])
                _save_png(os.path.join(d, f"{i:05d}_depth.png"),
                          np.clip(np.round(L["depth"] * 1000.0), 0, 65535).astype(np.uint16))
                names = [k for k in KEYPOINTS if k in fr.bike_keypoints]
                uv, z = project_points(np.stack([fr.bike_keypoints[k] for k in names]), cam)
                vis = keypoint_visibility(uv, z, L["alpha"], L["depth"], tolerances[0])
                kp = {"bike": {k: [float(uv[j, 0]), float(uv[j, 1]), int(vis[j])] for j, k in enumerate(names)},
                      "visibility": "0 outside the image, 1 occluded, 2 visible"}
                if fr.rider_joints is not None:
                    uvr, zr = project_points(fr.rider_joints, cam)
                    visr = keypoint_visibility(uvr, zr, L["alpha"], L["depth"], tolerances[1])
                    kp["rider"] = {k: [float(uvr[j, 0]), float(uvr[j, 1]), int(visr[j])] for j, k in enumerate(JOINT_NAMES)}
                write_json(os.path.join(d, f"{i:05d}_keypoints.json"), kp)
            if ply:
                write_ply(fr.gaussians, os.path.join(out, "ply", f"{i:05d}.ply"))
            write_json(os.path.join(out, f"frame_{i:05d}.json"),
                       frame_record(fr, i, dict(meta or {}, views=[view_name(a) for a in views])))
            k = todo.index(i) + 1
            el = time.time() - t0
            sys.stderr.write(f"cyclist: frame {i + 1}/{n} ({k}/{len(todo)} this run, {el / k:.2f} s/frame, "
                             f"eta {el / k * (len(todo) - k):.0f} s)\n")
    write_previews(out, n, views)
    return {"frames": n, "rendered": len(todo), "skipped": n - len(todo), "wall_s": time.time() - t0}


def write_previews(out, n, views, thumb=128):
    """preview.png: one row per view, up to 8 frames spread over the sequence, over white;
    preview.gif: the first view, every frame."""
    from PIL import Image
    cols = sorted(set(np.linspace(0, n - 1, min(n, MAX_PREVIEW_COLUMNS)).round().astype(int).tolist()))
    sheet = Image.new("RGB", (thumb * len(cols), thumb * len(views)), (255, 255, 255))
    for r, az in enumerate(views):
        for c, i in enumerate(cols):
            im = Image.open(os.path.join(out, view_name(az), f"{i:05d}.png")).convert("RGBA").resize((thumb, thumb))
            bg = Image.new("RGBA", im.size, (255, 255, 255, 255))
            sheet.paste(Image.alpha_composite(bg, im).convert("RGB"), (c * thumb, r * thumb))
    with atomic_path(os.path.join(out, "preview.png")) as tmp:
        sheet.save(tmp, format="PNG")
    frames = []
    for i in range(n):
        im = Image.open(os.path.join(out, view_name(views[0]), f"{i:05d}.png")).convert("RGBA")
        im = im.resize((min(256, im.width), min(256, im.height)))
        bg = Image.new("RGBA", im.size, (255, 255, 255, 255))
        frames.append(Image.alpha_composite(bg, im).convert("RGB"))
    with atomic_path(os.path.join(out, "preview.gif")) as tmp:
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:], duration=83, loop=0)


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
    from cyclist_formats import checks
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
    from splatting.dataset.config import _has_crank
    from splatting.rider.roster import load_roster
    riders = [args.rider] if args.rider else [r["id"] for r in load_roster()]
    if args.bike:
        bikes = [args.bike]
    else:
        root = args.bikes_root
        if not os.path.isdir(root):
            raise UserError(f"no bikes root {root}")
        bikes = sorted(b for b in os.listdir(root) if os.path.isfile(os.path.join(root, b, "keypoints.json"))
                       and _has_crank(os.path.join(root, b)))
    log(f"cyclist: {len(riders)} riders x {len(bikes)} bikes = {len(riders) * len(bikes)} combinations")
    for r in riders:
        for b in bikes:
            run_one(args, r, b, os.path.join(args.out, f"{r}__{os.path.basename(os.path.normpath(b))}"), log)
    return 0

"""A cyclist sequence: bike poses over frames (pedalling programme or a motion file), the rider
fitted by IK for the whole sequence at once, and every frame rendered from every view with its
instance ids, depth and 2D keypoints (the layout is in splatting/cyclist/command.py and
docs/contract.md).  `python -m splatting cyclist` is the command line over this."""
import math
import os
import sys
import time

from PIL import Image
import numpy as np
import roma
import torch

from cyclist_formats.atomic import atomic_path, write_json
from cyclist_formats.errors import UserError
from splatting.bike.model import KEYPOINTS
from splatting.bike.pose import posed_bike_keypoints
from splatting.cyclist.compose import frame_eps2d, frame_record, take_fit
from splatting.cyclist.render import (keypoint_visibility, orbit_camera, project_points, render_layers_cameras,
                                      rgba_image)
from splatting.gaussians.container import write_ply
from splatting.rider import ik
from splatting.rider.body import posed_joints
from splatting.rider.kinematics import JOINT_INDEX, JOINT_NAMES
from splatting.rider.motion import load_motion, theta_from_pose

MAX_PREVIEW_COLUMNS = 8


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
    res = cyc.fit_rider(poses, saddle_shared=True)
    if motion_aa is None:
        return res
    keep = [i for i, n in enumerate(JOINT_INDEX) if n not in ik.SLOT_JOINTS]
    init = res.local_aa.clone()
    init[:, keep] = motion_aa[:, keep]
    p = poses.clone()
    p[:, 2:] = 0.0
    targets = posed_bike_keypoints(cyc.bike.keypoints, p)
    return ik.solve(cyc.avatar.rest_joints, targets, init_local_aa=init, init_root=res.root_trans,
                    iterations=cyc.ik_iterations, saddle_fit=cyc.saddle_fit, saddle_shared=cyc.saddle_fit,
                    pairs=cyc.pairs)


def _save_png(path, arr):
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
    n = poses.shape[0]
    os.makedirs(out, exist_ok=True)
    # one orbit centre for the whole sequence (docs/contract.md: (x, h, z) of the first frame's box centre)
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
            # every view of the frame in one rasterization call (one pass of the C++ back end)
            layers = render_layers_cameras(fr.gaussians, fr.ids, list(cams.values()), antialiased=cyc.bike.antialiased,
                                           eps2d=frame_eps2d(fr.ids, cyc.bike, cyc.avatar))
            for (az, cam), L in zip(cams.items(), layers):
                d = os.path.join(out, view_name(az))
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



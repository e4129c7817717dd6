"""Motion blur of a sequence frame: the average of renders at sub-frame instants of the exposure.

A camera's shutter integrates light over its exposure; every Gaussian moves along its own path
meanwhile (the cyclist along its trajectory, its pedals with the crank phase, the ego camera along
the road), so a box-shutter image is the time average of the instantaneous images.  It is
approximated by `blur_subframes` (N, odd) renders at the midpoints of N equal slices of the
exposure, t_f + e ((k + 1/2) / N - 1/2): for odd N the middle one is the frame's instant itself,
so the labels are that render's (the mid-exposure instant) and cost no extra render.
bench/motion_blur.py measures N against a 33-sub-frame reference (docs/sequences.md, motion blur).

Sub-frame poses come from the trajectory's fine grid (20 steps per frame, linear interpolation;
the crank and heading unwrapped); before the first and after the last frame they continue
linearly (the path's velocity at its end).  The arm signal of the frame holds through its exposure.
"""
import numpy as np

from splatting.dataset.generate import make_sample
from splatting.dataset.sequences.draw import ego_camera, ego_camera_at, frame_draw, with_look


def subframe_offsets(exposure_s, n):
    """Times (s) of the n sub-frame instants relative to the frame's (the mid-exposure instant)."""
    k = np.arange(n)
    return exposure_s * ((k + 0.5) / n - 0.5)


def _lerp(t_grid, values, t):
    """values (n, 8) on the increasing grid t_grid at time t, continued linearly beyond its ends."""
    i = int(np.clip(np.searchsorted(t_grid, t) - 1, 0, len(t_grid) - 2))
    w = (t - t_grid[i]) / (t_grid[i + 1] - t_grid[i])
    return values[i] + w * (values[i + 1] - values[i])


def pose_at(inst, t):
    """An instance's 8-DoF pose at time t (s) of its sequence (a parked bike: its one pose)."""
    tr = inst["traj"]
    if "fine_pose" not in tr:
        return [float(x) for x in inst["poses"][0]]
    p = _lerp(tr["fine_t"], tr["fine_pose"], t)
    p[0] = p[0] % 360.0
    return [float(x) for x in p]


def wheel_at(inst, t):
    """{"wheel_deg": the wheels' rolling angle at time t} (spinning wheel sub-parts blur), or {}
    for an instance without a trajectory's wheel angle (a parked bike)."""
    tr = inst.get("traj", {})
    if "fine_wheel_deg" not in tr:
        return {}
    return {"wheel_deg": float(_lerp(tr["fine_t"], np.asarray(tr["fine_wheel_deg"])[:, None], t)[0])}


def subframe_draw(sd, f, t):
    """make_sample's draw at time t (s) of a sequence drawn by draw_sequence, frame f's signals."""
    inst = [{"kind": i["kind"], "bike": i["bike"], "rider": i["rider"], "pose": pose_at(i, t),
             **({"signal": i["signal"][f]} if "signal" in i else {}),
             **({"foot_down": i["foot_down"][f]} if i.get("foot_down", ["none"] * (f + 1))[f] != "none" else {}),
             **wheel_at(i, t)} for i in sd["instances"]]
    return with_look({"instances": inst, "dropped": sd["dropped"], "camera": dict(sd["camera"]),
                      "background": dict(sd["background"]), "subframe": True}, sd)


def blurred_sample(cfg, index, assets, sd, f, exposure_s, n):
    """(rgb uint8, image, annotations, extras) of frame f of the drawn sequence sd with motion blur:
    the mean of n (odd) renders at the sub-frame instants; labels and extras are those of the
    middle render, the frame's own draw and camera (exactly the unblurred frame's)."""
    t_f = f / float(cfg.sequence.fps)
    seq = index // int(cfg.sequence.length)
    acc, mid = None, n // 2
    for k, dt in enumerate(subframe_offsets(exposure_s, n)):
        if k == mid:  # exactly the frame's instant: its draw and camera, hence its labels
            out = make_sample(cfg, index, assets, drawn=frame_draw(sd, f), camera=ego_camera(sd, f), look_index=seq)
            rgb = out[0]
        else:
            t = t_f + dt
            rgb = make_sample(cfg, index, assets, drawn=subframe_draw(sd, f, t), look_index=seq,
                              camera=ego_camera_at(sd, sd["ego_speed"] * t))[0]
        acc = rgb.astype(np.float64) if acc is None else acc + rgb
    rgb = np.clip(np.rint(acc / n), 0, 255).astype(np.uint8)
    return (rgb,) + tuple(out[1:])

"""Both tyres on the road: the lowest points of the posed wheels, and the t_Y that seats them.

A wheel is the circle of radius r (its rest axle height above the `ground` keypoint) about its axle
in the bike's XY plane (canonical frame: X forward, Y up, Z right); the rear one moves with the
global transform, the front one with steering then the global transform (splatting.bike.pose, the
pose maths every bike uses).  Roll (theta_X) turns about the contact line, so only steering (the
front contact moves with the trail) and pitch (placement keeps theta_Z = 0) lift a tyre.
"""
import math

import numpy as np
import torch

from splatting.bike.pose import pose_transforms, transform_points

N_RIM = 720  # rim samples (0.5 deg: the lowest point within r (1 - cos 0.25 deg) ~ 3e-6 m)


def _rim(axle, r):
    phi = torch.linspace(0, 2 * math.pi, N_RIM + 1, dtype=torch.float64)[:-1]
    a = torch.as_tensor(axle, dtype=torch.float64)
    return torch.stack([a[0] + r * torch.cos(phi), a[1] + r * torch.sin(phi), a[2].expand(N_RIM)], 1)


def tyre_heights(keypoints, pose):
    """(front, rear) lowest world Y (m) of the posed tyres: their heights above the road Y = 0."""
    kp = {k: torch.as_tensor(v, dtype=torch.float64) for k, v in keypoints.items()}
    g0 = float(kp["ground"][1]) if "ground" in kp else 0.0
    H = pose_transforms(np.asarray(pose, float)[None], kp["steer_bottom"], kp["steer_top"])
    out = []
    for name, Hs in (("front_axle", H["global"][0] @ H["steer"][0]), ("rear_axle", H["global"][0])):
        r = float(kp[name][1]) - g0
        out.append(float(transform_points(Hs, _rim(kp[name], r))[:, 1].min()))
    return tuple(out)


def seat(keypoints, pose):
    """pose (8,) with t_Y set so that the two tyres' lowest points straddle the road equally (each
    within half their difference of it)."""
    p = [float(x) for x in pose]
    p[6] = 0.0
    f, r = tyre_heights(keypoints, p)
    p[6] = -(f + r) / 2.0
    return p

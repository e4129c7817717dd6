"""The 8-DoF bicycle pose (docs/contract.md): parsing, validation and the rigid transforms H_s, H_p, H_g.

pose = (theta_p, theta_s, theta_X, theta_Y, theta_Z, t_X, t_Y, t_Z); degrees and metres in files
and on the command line, radians inside.  Canonical frame: X forward, Y up, Z to the rider's right.

- H_s: rotation by +theta_s about v = normalise(steer_top - steer_bottom) through steer_bottom.
  v points up (and back), so +theta_s swings the front wheel towards -Z (the rider's left).
- H_p: rotation by -theta_p about +Z through crank_axle (+theta_p = forward pedalling).
- H_g = T(t) Rz(theta_Z) Ry(theta_Y) Rx(theta_X), applied after H_s / H_p.

Rigid maps are (R, t, L) triples inside (L: the 4x4 left-product matrix of the rotation's wxyz
quaternion) and (..., 4, 4) homogeneous matrices in the public API; batched over poses, float64.
Applying one to Gaussians moves means, quaternions (left product) and SH (sh_rotation);
log-scales and opacities are rotation invariant and stay.
"""
import math
from dataclasses import replace

import numpy as np
import torch

from cyclist_formats import pose as formats_pose
from cyclist_formats.bike_folder import DEFAULT_KEYPOINT_PARTS
from cyclist_formats.errors import UserError
from cyclist_formats.pose import N_ANGLES
from splatting.gaussians.container import Gaussians
from splatting.gaussians.sh_rotation import rotate_sh
from splatting.rotations import quat_left_matrix, rotmat_to_quat_wxyz  # noqa: F401

MIN_STEER_AXIS_M = 1e-6  # steer_top and steer_bottom closer than this do not define an axis


# ---------------------------------------------------------------- parsing and validation
# cyclist_formats.pose owns the fields and their parsing (numpy); these hand torch float64 on.

def check_poses(poses):
    """Any (8,) or (B, 8) array-like of degrees/metres -> float64 tensor (B, 8); UserError if bad."""
    if isinstance(poses, torch.Tensor):
        poses = poses.detach().cpu().double().numpy()
    return torch.from_numpy(formats_pose.check_poses(poses))


def parse_pose_string(text):
    """'p,s,X,Y,Z,tx,ty,tz' (degrees, metres) -> float64 tensor (8,)."""
    return torch.from_numpy(formats_pose.parse_pose_string(text))


def poses_from_json(obj):
    """A list of 8-lists or of dicts with the named POSE_FIELDS (or {"poses": [...]}) -> (B, 8)."""
    return torch.from_numpy(formats_pose.poses_from_json(obj))


def pose_dict(pose):
    """(8,) degrees/metres -> {field: value} for JSON output."""
    return formats_pose.pose_dict(pose.detach().cpu().numpy() if isinstance(pose, torch.Tensor) else pose)


# ---------------------------------------------------------------- transforms
# Closed-form Rodrigues + axis quaternions for all elementary rotations in one batched call,
# instead of roma's general euler/rotvec/rotmat->quat conversions: measured 0.14 ms vs 0.6-0.9 ms
# per pose for the same transforms (1 thread, noisy shared cores) - a real share of the 5 ms
# budget for re-posing 100k Gaussians.  roma is still used for rotation matrix -> quaternion in
# the generic transform_gaussians path.

X_AXIS, Y_AXIS, Z_AXIS = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def cross_matrix(v):
    """(..., 3) -> (..., 3, 3) K with K @ w == v x w."""
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([o, -z, y, z, o, -x, -y, x, o], -1).reshape(v.shape[:-1] + (3, 3))


def axis_rotations(axes, angles):
    """Right-hand rotations about unit axes (A, 3) by angles (B, A) radians ->
    R (B, A, 3, 3) (Rodrigues) and L (B, A, 4, 4), the left-product matrix of the same rotation's
    wxyz quaternion (q * p == L @ p)."""
    K = cross_matrix(axes.to(angles.dtype))
    s, c = torch.sin(angles)[..., None, None], torch.cos(angles)[..., None, None]
    R = torch.eye(3, dtype=angles.dtype) + s * K + (1.0 - c) * (K @ K)
    h = 0.5 * angles[..., None]
    q = torch.cat([torch.cos(h), torch.sin(h) * axes.to(angles.dtype)], -1)
    return R, quat_left_matrix(q)


def rigid(R, t):
    """R (..., 3, 3), t (..., 3) -> homogeneous (..., 4, 4)."""
    H = R.new_zeros(R.shape[:-2] + (4, 4))
    H[..., :3, :3] = R
    H[..., :3, 3] = t
    H[..., 3, 3] = 1.0
    return H


def steering_axis(steer_bottom, steer_top):
    """Unit vector steer_bottom -> steer_top; UserError when the two keypoints coincide."""
    d = torch.as_tensor(steer_top, dtype=torch.float64) - torch.as_tensor(steer_bottom, dtype=torch.float64)
    n = float(torch.linalg.vector_norm(d))
    if not n > MIN_STEER_AXIS_M:
        raise UserError(f"steer_top and steer_bottom coincide ({n:.3g} m apart): no steering axis")
    return d / n


def pose_rotations(poses_deg, steer_axis_unit, extra_axes=()):
    """The elementary rotations of a pose batch, all in one call:
    (B, 8) degrees/metres -> R (B, 5 + E, 3, 3), L (B, 5 + E, 4, 4) for
    [Rx(theta_X), Ry(theta_Y), Rz(theta_Z), steer(+theta_s about v), pedal(-theta_p about +Z)]
    followed by one rotation per (axis, angles (B,)) pair in extra_axes."""
    ang = poses_deg[:, :N_ANGLES] * (math.pi / 180.0)
    axes = [torch.tensor([X_AXIS, Y_AXIS, Z_AXIS], dtype=torch.float64), steer_axis_unit[None],
            torch.tensor([Z_AXIS], dtype=torch.float64)]
    angles = [ang[:, 2:5], ang[:, 1:2], -ang[:, 0:1]]
    for axis, a in extra_axes:
        axes.append(torch.as_tensor(axis, dtype=torch.float64)[None])
        angles.append(a[:, None])
    return axis_rotations(torch.cat(axes), torch.cat(angles, 1))


def about_point(R, L, point):
    """A rotation (R, L) about an axis through `point` (3,) -> rigid (R, t, L), t = p - R p."""
    return R, point - R @ point, L


def compose(a, b):
    """Rigid maps as (R, t, L) triples: (a o b)(x) = a(b(x))."""
    Ra, ta, La = a
    Rb, tb, Lb = b
    return Ra @ Rb, (Ra @ tb[..., None])[..., 0] + ta, La @ Lb


def global_rigid(R, L, poses_deg):
    """H_g = T(t) Rz Ry Rx from pose_rotations' output -> (R, t, L), each batched over B."""
    Rg = R[:, 2] @ R[:, 1] @ R[:, 0]
    Lg = L[:, 2] @ L[:, 1] @ L[:, 0]
    return Rg, poses_deg[:, 5:8], Lg


def pose_transforms(poses_deg, steer_bottom, steer_top, crank_axle=None):
    """(B, 8) degrees/metres -> dict of (B, 4, 4) float64 homogeneous matrices: 'steer' H_s,
    'pedal' H_p (None without a crank), 'global' H_g."""
    p = check_poses(poses_deg)
    bottom = torch.as_tensor(steer_bottom, dtype=torch.float64)
    R, L = pose_rotations(p, steering_axis(bottom, steer_top))
    out = {"steer": rigid(*about_point(R[:, 3], L[:, 3], bottom)[:2]), "pedal": None,
           "global": rigid(*global_rigid(R, L, p)[:2])}
    if crank_axle is not None:
        out["pedal"] = rigid(*about_point(R[:, 4], L[:, 4], torch.as_tensor(crank_axle, dtype=torch.float64))[:2])
    return out


# ---------------------------------------------------------------- applying transforms

def transform_points(H, pts):
    """H (..., 4, 4), pts (..., 3) (broadcast) -> (..., 3)."""
    H = H.to(pts.dtype)
    return (H[..., :3, :3] @ pts[..., None])[..., 0] + H[..., :3, 3]


def transform_gaussians(g: Gaussians, H) -> Gaussians:
    """One rigid transform H (4, 4) applied to a Gaussian set (simple reference path; the bike
    model uses its own batched, preallocated path)."""
    H = torch.as_tensor(H, dtype=torch.float64)
    R = H[:3, :3]
    dt = g.means.dtype
    q = rotmat_to_quat_wxyz(R).to(dt)
    return replace(
        g,
        means=transform_points(H.to(dt), g.means),
        quats=g.quats @ quat_left_matrix(q).T,
        sh=rotate_sh(g.sh, R.to(dt)),
    )


def sample_poses(n, seed=0):
    """n random 8-DoF poses (degrees, metres; docs/contract.md) and n ring camera indices (0..35), a
    function of the seed alone: the ground-truth checks (library gt, bench/bike_gt) score these poses
    and the posed fine-tune trains on other seeds of it (bike.posed_train.training_poses)."""
    rng = np.random.default_rng(seed)
    poses = np.stack([
        rng.uniform(0, 360, n),      # theta_p: full circle
        rng.uniform(-60, 60, n),     # theta_s
        rng.uniform(-15, 15, n),     # roll (about X)
        rng.uniform(0, 360, n),      # yaw (about Y, up)
        rng.uniform(-15, 15, n),     # pitch (about Z)
        rng.uniform(-0.3, 0.3, n),   # t_x
        rng.uniform(-0.1, 0.1, n),   # t_y
        rng.uniform(-0.3, 0.3, n),   # t_z
    ], 1)
    cams = rng.integers(0, 36, n)
    return poses, cams


def posed_bike_keypoints(keypoints, poses_deg):
    """Bike keypoints {name: (3,)} (canonical, rest) at B 8-DoF poses (docs/contract.md, degrees and
    metres) -> {name: (B, 3) float64}: steering keypoints turn with theta_s, pedals with theta_p,
    then the global transform.  What the IK needs without loading a BikeModel's Gaussians."""
    kp = {k: torch.as_tensor(v, dtype=torch.float64) for k, v in keypoints.items()}
    H = pose_transforms(poses_deg, kp["steer_bottom"], kp["steer_top"], kp.get("crank_axle"))
    part = {k: p for p, ks in DEFAULT_KEYPOINT_PARTS.items() for k in ks}
    out = {}
    for k, x in kp.items():
        local = {"steering": H["steer"], "crank": H["pedal"]}.get(part.get(k))
        y = transform_points(local, x) if local is not None else x.expand(H["global"].shape[0], 3)
        out[k] = transform_points(H["global"], y)
    return out

"""Where the IK optimiser starts: a generic seated pedalling pose, a target-aware analytic start
(torso lean from the handle reach, two-bone limbs toward their targets) and the saddle height
that lets the legs reach the pedals.  Adam from a generic start needs ~100 iterations for 1 cm;
from this start 50 are enough (docs/ik.md)."""
import math

import numpy as np
import roma
import torch

from splatting.rider.ik.slots import DEFAULT_PAIRS, HINGE_SLOTS, SLOT_JOINTS, hinge_axes, skeleton_key
from splatting.rider.kinematics import JOINT_INDEX
from splatting.rotations import rotmat_to_axis_angle as _rotmat_to_aa

def _align(u, d):
    """Axis-angle of the smallest rotation taking direction u to direction d (numpy)."""
    u, d = u / np.linalg.norm(u), d / np.linalg.norm(d)
    ax = np.cross(u, d)
    s, c = np.linalg.norm(ax), float(np.dot(u, d))
    return ax / s * math.atan2(s, c) if s > 1e-9 else np.zeros(3)


_CYCLING = {}


def cycling_init_pose(rest_joints):
    """(24, 3) axis-angle: a generic seated pedalling pose for this rest skeleton (torso leaning
    ~30 deg forward, thighs forward, knees and elbows bent), the default IK start.  Bent hinges
    matter: at a straight knee the gradient along the leg vanishes.  Computed once per skeleton
    (~4 ms of small-array work; the analytic start needs it for every dataset image)."""
    key = skeleton_key(rest_joints)
    if key not in _CYCLING:
        _CYCLING[key] = _cycling_init_pose(np.asarray(rest_joints, dtype=np.float64))
    return _CYCLING[key].copy()


def _cycling_init_pose(rest):
    axes = hinge_axes(rest).numpy()
    aa = np.zeros((24, 3))
    lean = np.array([0.0, 0.0, -math.radians(30)])  # about -Z: the torso tips toward +X
    aa[JOINT_INDEX["spine1"]] = lean
    R_lean = roma.rotvec_to_rotmat(torch.tensor(lean)).numpy()
    for side, sz in (("left", -1.0), ("right", 1.0)):
        hip, knee = JOINT_INDEX[f"{side}_hip"], JOINT_INDEX[f"{side}_knee"]
        aa[hip] = _align(rest[knee] - rest[hip], np.array([0.55, -0.83, 0.0]))  # thigh ~56 deg up
        aa[knee] = axes[SLOT_JOINTS[HINGE_SLOTS].index(f"{side}_knee")] * 1.4
        sh, el = JOINT_INDEX[f"{side}_shoulder"], JOINT_INDEX[f"{side}_elbow"]
        world = _align(rest[el] - rest[sh], np.array([0.55, -0.8, 0.15 * sz]))
        # local = R_parent^T * world rotation; the parent chain (spine1..collar) carries the lean
        Rw = roma.rotvec_to_rotmat(torch.tensor(world)).numpy()
        aa[sh] = roma.rotmat_to_rotvec(torch.tensor(R_lean.T @ Rw)).numpy()
        aa[el] = axes[SLOT_JOINTS[HINGE_SLOTS].index(f"{side}_elbow")] * 0.5
    return aa


def _frame(u, a):
    """(..., 3) unit u and a unit a perpendicular to it -> (..., 3, 3) with columns u, a, u x a."""
    return torch.stack([u, a, torch.linalg.cross(u, a)], -1)


def _unit(x):
    return x / torch.linalg.vector_norm(x, dim=-1, keepdim=True).clamp_min(1e-12)


def _two_bone(start, target, l1, v, u0, a0, pole):
    """Analytic two-segment limb (B frames) from `start` toward `target` (B, 3), middle joint
    bulging toward `pole` (3,).  Rest geometry: first segment l1 along unit u0, hinge axis a0 (unit,
    perpendicular to u0), second segment vector v (rest skeletons are rarely straight: v may leave
    the u0 line and the hinge plane).  -> first-segment direction u1 (B, 3), world hinge axis
    (B, 3), hinge angle theta (B,) about a0.  Out-of-reach targets get the limb stretched at them."""
    v_a = float(v @ a0)
    v_p = v - v_a * a0
    l2 = float(torch.linalg.vector_norm(v_p))
    theta_rest = math.atan2(float(torch.linalg.cross(u0, v_p) @ a0), float(u0 @ v_p))
    d = target - start
    a_w = torch.zeros_like(d)
    for _ in range(3):  # the out-of-plane part v_a * a_w depends on the plane: a few fixed-point steps
        dp = d - v_a * a_w
        e = _unit(dp)
        n = pole - (pole * e).sum(-1, keepdim=True) * e
        bad = torch.linalg.vector_norm(n, dim=-1) < 1e-6  # pole along the limb: any normal will do
        n[bad] = torch.linalg.cross(e[bad], torch.tensor([0.0, 0.0, 1.0], dtype=e.dtype).expand_as(e[bad]))
        n = _unit(n)
        a_w = _unit(torch.linalg.cross(n, e))
    Dc = torch.linalg.vector_norm(dp, dim=-1).clamp(abs(l1 - l2) + 1e-3, l1 + l2 - 1e-6)
    cos_a = ((l1 * l1 + Dc * Dc - l2 * l2) / (2 * l1 * Dc)).clamp(-1, 1)
    u1 = cos_a[:, None] * e + torch.sqrt(1 - cos_a ** 2)[:, None] * n
    cos_g = ((l1 * l1 + l2 * l2 - Dc * Dc) / (2 * l1 * l2)).clamp(-1, 1)
    return u1, a_w, math.pi - torch.acos(cos_g) - theta_rest


KNEE_POLE = (1.0, 0.0, 0.0)          # knees point forward
ELBOW_POLE = (-0.3, -1.0, 0.6)       # elbows point down, back and out (Z sign per side)
ARM_REACH_FRACTION = 0.9             # torso lean chosen so shoulder->handle is 0.9 of the arm


def analytic_init_pose(rest_joints, targets, pairs=DEFAULT_PAIRS):
    """A target-aware start for the optimiser (B frames): root upright with the pelvis on its
    target, torso lean chosen so the handles are ARM_REACH_FRACTION of the arm's reach from the
    shoulders, and two-bone analytic IK for each leg and arm whose end joint has a target (knees
    forward, elbows down/out).  Limbs without a target keep cycling_init_pose.
    rest_joints (24, 3); targets name -> (B, 3) float64, the pelvis's target already lifted above
    the seat -> (aa (B, 24, 3), root_trans (B, 3))."""
    rest = torch.as_tensor(rest_joints, dtype=torch.float64)
    B = next(iter(targets.values())).shape[0]
    generic = torch.as_tensor(cycling_init_pose(rest.numpy()))
    aa = generic.expand(B, 24, 3).clone()
    of = {j: t for j, t in pairs}
    pelvis = targets[of["pelvis"]] if "pelvis" in of else rest[0].expand(B, 3)
    trans = pelvis - rest[0]
    axes = dict(zip(SLOT_JOINTS[HINGE_SLOTS], hinge_axes(rest)))
    J = lambda n: rest[JOINT_INDEX[n]]  # noqa: E731
    seg = lambda a, b: float(torch.linalg.vector_norm(J(b) - J(a)))  # noqa: E731
    # torso lean about the lateral axis, from a grid (vectorised over frames)
    hands = [(s, of[f"{s}_wrist"]) for s in ("left", "right") if f"{s}_wrist" in of]
    R_lean = roma.rotvec_to_rotmat(generic[JOINT_INDEX["spine1"]]).expand(B, 3, 3)
    if hands:
        phi = torch.linspace(0.0, math.radians(85), 35, dtype=torch.float64)
        R_grid = roma.rotvec_to_rotmat(phi[:, None] * torch.tensor([0.0, 0.0, -1.0], dtype=torch.float64))
        spine1 = trans + J("spine1")
        err = 0
        for s, t in hands:
            reach = ARM_REACH_FRACTION * (seg(f"{s}_shoulder", f"{s}_elbow") + seg(f"{s}_elbow", f"{s}_wrist"))
            sh = spine1[:, None] + (R_grid @ (J(f"{s}_shoulder") - J("spine1")))[None]  # (B, G, 3)
            err = err + (torch.linalg.vector_norm(targets[t][:, None] - sh, dim=-1) - reach).abs()
        best = err.argmin(1)
        R_lean = R_grid[best]
        local_R = {"spine1": R_lean}
    else:
        local_R = {}
    for s, sz in (("left", -1.0), ("right", 1.0)):
        for a, b, c, pole, parent_R, origin in (
                (f"{s}_hip", f"{s}_knee", f"{s}_ankle", KNEE_POLE, None, trans),
                (f"{s}_shoulder", f"{s}_elbow", f"{s}_wrist", ELBOW_POLE, R_lean, None)):
            if c not in of:
                continue
            if parent_R is None:
                start = origin + J(a)
            else:
                start = trans + J("spine1") + (parent_R @ (J(a) - J("spine1")))
            pole_t = torch.tensor([pole[0], pole[1], pole[2] * sz], dtype=torch.float64)
            u0 = _unit(J(b) - J(a))
            u1, axis_w, theta = _two_bone(start, targets[of[c]], seg(a, b), J(c) - J(b), u0, axes[b], pole_t)
            R_w = _frame(u1, axis_w) @ _frame(u0, axes[b]).T
            local_R[a] = R_w if parent_R is None else parent_R.transpose(-1, -2) @ R_w
            aa[:, JOINT_INDEX[b]] = theta[:, None] * axes[b]
    if local_R:  # one conversion for every joint set above (per-matrix maths: the same values)
        rv = _rotmat_to_aa(torch.cat(list(local_R.values()))).view(len(local_R), B, 3)
        for name, v in zip(local_R, rv):
            aa[:, JOINT_INDEX[name]] = v
    return aa, trans


SADDLE_LEG_EXTENSION = 0.97  # hip-ankle distance / leg length at the fitted saddle: knee ~30 deg
# bent at the farthest pedal, the usual saddle-height rule (25-35 deg at bottom dead centre)


def saddle_offset_for_reach(rest_joints, T, U, pairs, lo, hi, extension=SADDLE_LEG_EXTENSION):
    """Seat offset s (B,) along the seat tube, within [lo, hi], that brings both hip joints within
    `extension` of the leg length from their pedal targets (0 when they already are; lo when no
    offset can).  T (B, P, 3) pair targets (pelvis lifted), U (B, P, 3) the unit seat-tube
    direction on the pelvis pair's row.  Solves |pedal - hip(0) - s u| = reach per leg."""
    rest = torch.as_tensor(rest_joints, dtype=torch.float64)
    of = {j: k for k, (j, _) in enumerate(pairs)}
    if "pelvis" not in of:
        return torch.zeros(T.shape[0], dtype=torch.float64)
    k = of["pelvis"]
    u = U[:, k]
    s_lo = torch.full((T.shape[0],), -math.inf, dtype=torch.float64)
    s_hi = torch.full((T.shape[0],), math.inf, dtype=torch.float64)
    for side in ("left", "right"):
        if f"{side}_ankle" not in of:
            continue
        hip = T[:, k] + rest[JOINT_INDEX[f"{side}_hip"]] - rest[0]
        reach = extension * float(torch.linalg.vector_norm(rest[JOINT_INDEX[f"{side}_knee"]] - rest[JOINT_INDEX[f"{side}_hip"]])
                                  + torch.linalg.vector_norm(rest[JOINT_INDEX[f"{side}_ankle"]] - rest[JOINT_INDEX[f"{side}_knee"]]))
        w = T[:, of[f"{side}_ankle"]] - hip
        wu = (w * u).sum(-1)
        disc = wu ** 2 - (w * w).sum(-1) + reach ** 2
        root = disc.clamp_min(0).sqrt()
        ok = disc >= 0
        s_lo = torch.where(ok, torch.maximum(s_lo, wu - root), s_lo)
        s_hi = torch.where(ok, torch.minimum(s_hi, wu + root), torch.full_like(s_hi, lo))
    s = torch.minimum(torch.maximum(torch.zeros_like(s_lo), s_lo), s_hi)
    return s.clamp(lo, hi)

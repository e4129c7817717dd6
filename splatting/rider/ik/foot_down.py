"""A foot on the ground at a stop: the IK with one foot off its pedal, that leg set explicitly.

A stopped rider stays on the saddle with both hands on the grips and the other foot on its pedal
(the ordinary IK with the grounded foot's pair left out), leans the bike towards the grounded
side (the pose's theta_X, FOOT_DOWN_LEAN_DEG), and that leg is set by the analytic two-bone limb
of start.py (hip -> knee -> ankle, the knee forward) toward an ankle target on the road beside
the bike: ANKLE_ABOVE_GROUND_M over the ground plane, FOOT_OUT_M out from the bike's plane and
FOOT_AHEAD_M ahead of the crank axle, measured in the world (the leaning bike's road).  The IK
runs in the bike's frame, so the target is the world point brought into it through theta_X.
A leg too short for the road at that lean is stretched toward it: `ground_gap_m` reports how
far the ankle stays from its target.  docs/sequences.md ("Foot down").
"""
import math

import torch

from splatting.rider.ik.signals import merge_results, released, solve_in_groups
from splatting.rider.ik.slots import HINGE_SLOTS, SLOT_JOINTS, hinge_axes, pair_name
from splatting.rider.ik.start import KNEE_POLE, _frame, _two_bone, _unit
from splatting.rider.kinematics import JOINT_INDEX, PARENTS, forward_kinematics
from splatting.rotations import rodrigues, rotmat_to_axis_angle

FEET = ("none", "left", "right")
FOOT_DOWN_LEAN_DEG = 8.0      # how far the stopped bike leans towards the grounded foot
ANKLE_ABOVE_GROUND_M = 0.08   # the SMPL ankle joint's height over the sole
FOOT_OUT_M = 0.30             # the ankle's distance from the bike's plane, on the road
FOOT_AHEAD_M = 0.05           # ... and ahead of the crank axle


def _side(side):
    return -1.0 if side == "left" else 1.0  # canonical Z points to the rider's right


def lean_deg(foot):
    """theta_X of a bike whose rider has `foot` down (leaning towards it: left is negative)."""
    return 0.0 if foot in (None, "none") else _side(foot) * FOOT_DOWN_LEAN_DEG


def ankle_target(foot, crank_axle, theta_x_deg):
    """(3,) the grounded ankle's target in the bike's frame for a bike leaning by theta_x_deg:
    the world point (crank_axle.x + FOOT_AHEAD_M, ANKLE_ABOVE_GROUND_M, +-FOOT_OUT_M) through Rx^-1."""
    a = math.radians(float(theta_x_deg))
    w = torch.tensor([float(crank_axle[0]) + FOOT_AHEAD_M, ANKLE_ABOVE_GROUND_M, _side(foot) * FOOT_OUT_M],
                     dtype=torch.float64)
    c, s = math.cos(a), math.sin(a)
    Rx = torch.tensor([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]], dtype=torch.float64)
    return Rx.T @ w


def pose_leg(rest, local_aa, root_trans, foot, target):
    """Set the leg of `foot` in local_aa (B, 24, 3) (in place) toward the ankle target (3,) ->
    posed joints (B, 24, 3); the pelvis is taken as the IK left it."""
    hip, knee, ankle = (JOINT_INDEX[f"{foot}_{n}"] for n in ("hip", "knee", "ankle"))
    joints, T = forward_kinematics(rest, rodrigues(local_aa.double()), root_trans.double())
    R_parent = T[:, PARENTS[hip], :3, :3]
    l1 = float(torch.linalg.vector_norm(rest[knee] - rest[hip]))
    a0 = hinge_axes(rest)[list(SLOT_JOINTS[HINGE_SLOTS]).index(f"{foot}_knee")]
    u0 = _unit(rest[knee] - rest[hip])
    pole = torch.tensor(KNEE_POLE, dtype=torch.float64) + torch.tensor([0.0, 0.0, 0.3 * _side(foot)], dtype=torch.float64)
    tgt = target.to(torch.float64).expand(len(local_aa), 3)
    u1, axis_w, theta = _two_bone(joints[:, hip], tgt, l1, rest[ankle] - rest[knee], u0, a0, pole)
    R_w = _frame(u1, axis_w) @ _frame(u0, a0).T
    local_aa[:, hip] = rotmat_to_axis_angle(R_parent.transpose(-1, -2) @ R_w).to(local_aa.dtype)
    local_aa[:, knee] = (theta.clamp_min(0.0)[:, None] * a0).to(local_aa.dtype)
    local_aa[:, ankle] = 0.0  # the foot flat, as at rest
    joints, _ = forward_kinematics(rest, rodrigues(local_aa.double()), root_trans.double())
    return joints


def solve_with_feet(rest_joints, targets, feet, pairs, crank_axle, theta_x_deg, **kw):
    """ik.solve for B frames where frame b has feet[b] (one of FEET) on the ground and its bike
    leans by theta_x_deg[b]: frames are solved in groups by grounded foot (that foot's pedal pair
    left out), the leg then set by pose_leg.  Returns an IKResult over all B frames, `free`
    marking the released pedal pair and `ground_gap_m` (B,) the grounded ankle's distance from its
    target (0 where no foot is down or the leg reaches)."""
    bad = [f for f in feet if f not in FEET]
    if bad:
        raise ValueError(f"unknown foot {bad[0]!r} (known: {', '.join(FEET)})")
    rest = torch.as_tensor(rest_joints, dtype=torch.float64)
    B = len(feet)
    names = [pair_name(j, t) for j, t in pairs]
    gap = torch.zeros(B, dtype=torch.float32)
    parts = []
    for foot, idx, tg, res in solve_in_groups(rest, targets, [None if f == "none" else f for f in feet], pairs,
                                              "ankle", **kw):
        free_name = None
        if foot is not None:
            la = res.local_aa.clone()
            for k, b in enumerate(idx):
                row = la[k:k + 1]
                target = ankle_target(foot, crank_axle, theta_x_deg[b])
                joints = pose_leg(rest, row, res.root_trans[k:k + 1], foot, target)
                la[k] = row[0]
                gap[b] = float(torch.linalg.vector_norm(joints[0, JOINT_INDEX[f"{foot}_ankle"]] - target))
            joints, _ = forward_kinematics(rest, rodrigues(la.double()), res.root_trans.double())
            res.local_aa, res.joints = la, joints.to(res.joints.dtype)
            pedal = dict(pairs).get(f"{foot}_ankle")
            if pedal is not None:  # the grounded foot: its distance from its pedal (reported, never flagged)
                free_name = pair_name(f"{foot}_ankle", pedal)
                tgt = tg[pedal].to(torch.float64).reshape(-1, 3).expand(len(idx), 3)
                res.residuals[free_name] = torch.linalg.vector_norm(joints[:, JOINT_INDEX[f"{foot}_ankle"]] - tgt, dim=-1).float()
                res.flagged[free_name] = torch.zeros(len(idx), dtype=torch.bool)
        res.ground_gap_m = gap[idx]
        parts.append((idx, released(res, names, free_name)))
    return merge_results(B, parts, names=names)


def combine(B, parts):
    """IKResults of disjoint frame subsets [(frame indices, IKResult), ...] -> one IKResult over B
    frames in order (a batch where some frames have a foot down and others an arm signal)."""
    res = merge_results(B, parts)
    if getattr(res, "ground_gap_m", None) is None:
        res.ground_gap_m = torch.zeros(B, dtype=torch.float32)
    return res

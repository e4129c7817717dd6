"""Arm signals and one-handed riding: the IK with one hand off the bar, that arm posed explicitly.

A signalling rider keeps the other hand on its grip, the pelvis on the saddle and the feet on the
pedals (the ordinary IK with the free hand's pair left out, so steering stays that of the bike's
pose), then the free arm is set by the analytic two-bone limb of start.py toward a wrist target
fixed in the bike's frame (X forward, Y up, Z to the rider's right; the IK runs in that frame):

  left        left arm straight out sideways: shoulder abducted 90 deg, elbow straight
  right       right arm straight out sideways (the mirror)
  stop        left upper arm straight out sideways, elbow bent 90 deg, forearm pointing down
              (the "stop / slow down" arm signal of the US Uniform Vehicle Code 11-605 and most
              state driver manuals; the flexing elbow with the forearm down leaves the palm facing back)
  one_handed  left hand off the bar, the arm hanging relaxed beside the body (elbow bent ~20 deg)

The straight-arm signals ask for a wrist beyond the arm's reach along the sideways line, which the
two-bone limb meets with the arm stretched toward it: the wrist lies on the horizontal line through
the shoulder.  The wrist and hand rotations are not part of the IK, so the palm's turn is the
rest skeleton's.  docs/sequences.md (signals).
"""
import math

import torch

from cyclist_formats.errors import UserError
from splatting.rider.ik.slots import SLOT_JOINTS, HINGE_SLOTS, hinge_axes, pair_name
from splatting.rider.ik.solver import solve
from splatting.rider.ik.start import _frame, _two_bone, _unit
from splatting.rider.kinematics import JOINT_INDEX, PARENTS, forward_kinematics
from splatting.rotations import rodrigues, rotmat_to_axis_angle

SIGNALS = ("none", "left", "right", "stop", "one_handed")
FREE_HAND = {"left": "left", "right": "right", "stop": "left", "one_handed": "left"}  # the hand off the bar
HANG_ELBOW_RAD = math.radians(20.0)  # one-handed: the hanging arm's slight bend
HANG_DIRECTION = (0.15, -0.95, 0.25)  # one-handed: shoulder -> wrist, forward / down / outward (Z per side)


def _side_sign(side):
    return -1.0 if side == "left" else 1.0  # canonical Z points to the rider's right


def wrist_target(signal, shoulder, l1, l2):
    """(B, 3) wrist target and (3,) elbow pole of `signal` for shoulders at (B, 3) (bike frame)."""
    side = FREE_HAND[signal]
    sz = _side_sign(side)
    out = torch.tensor([0.0, 0.0, sz], dtype=shoulder.dtype)
    down = torch.tensor([0.0, -1.0, 0.0], dtype=shoulder.dtype)
    if signal in ("left", "right"):  # beyond reach along the sideways line: the limb stretches at it
        return shoulder + 1.2 * (l1 + l2) * out, torch.tensor([-0.2, -1.0, 0.0], dtype=shoulder.dtype)
    if signal == "stop":  # elbow at shoulder + l1 sideways, the forearm straight down from it
        return shoulder + l1 * out + l2 * down, out + 0.3 * torch.tensor([0.0, 1.0, 0.0], dtype=shoulder.dtype)
    # one-handed: a relaxed arm, elbow bent HANG_ELBOW_RAD (the wrist at the law-of-cosines distance)
    reach = math.sqrt(l1 * l1 + l2 * l2 + 2 * l1 * l2 * math.cos(HANG_ELBOW_RAD))
    d = _unit(torch.tensor([HANG_DIRECTION[0], HANG_DIRECTION[1], HANG_DIRECTION[2] * sz], dtype=shoulder.dtype))
    return shoulder + reach * d, torch.tensor([-1.0, 0.0, 0.3 * sz], dtype=shoulder.dtype)


def pose_arm(rest, local_aa, root_trans, signal):
    """Set the free arm of `signal` in local_aa (B, 24, 3) (in place) -> posed joints (B, 24, 3).
    rest (24, 3) float64; the parent chain (root, spine, collar) is taken as the IK left it."""
    side = FREE_HAND[signal]
    sh, el, wr = (JOINT_INDEX[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist"))
    R_local = rodrigues(local_aa.double())
    joints, T = forward_kinematics(rest, R_local, root_trans.double())
    R_parent = T[:, PARENTS[sh], :3, :3]
    l1 = float(torch.linalg.vector_norm(rest[el] - rest[sh]))
    l2 = float(torch.linalg.vector_norm(rest[wr] - rest[el]))
    target, pole = wrist_target(signal, joints[:, sh], l1, l2)
    a0 = hinge_axes(rest)[list(SLOT_JOINTS[HINGE_SLOTS]).index(f"{side}_elbow")]
    u0 = _unit(rest[el] - rest[sh])
    u1, axis_w, theta = _two_bone(joints[:, sh], target, l1, rest[wr] - rest[el], u0, a0, pole)
    R_w = _frame(u1, axis_w) @ _frame(u0, a0).T  # the upper arm's world rotation (rest -> posed)
    local_aa[:, sh] = rotmat_to_axis_angle(R_parent.transpose(-1, -2) @ R_w).to(local_aa.dtype)
    local_aa[:, el] = (theta.clamp_min(0.0)[:, None] * a0).to(local_aa.dtype)
    joints, _ = forward_kinematics(rest, rodrigues(local_aa.double()), root_trans.double())
    return joints


def solve_with_signals(rest_joints, targets, signals, pairs, **kw):
    """ik.solve for B frames where frame b shows signals[b] (one of SIGNALS): frames are solved in
    groups by free hand (that hand's pair left out), the free arm then posed by pose_arm.  Returns
    an IKResult over all B frames in order, with `free` {pair: (B,) bool} marking the released
    hand's pair (its residual is the wrist's distance from the grip, not an IK error)."""
    bad = [s for s in signals if s not in SIGNALS]
    if bad:
        raise UserError(f"unknown arm signal {bad[0]!r} (known: {', '.join(SIGNALS)})")
    rest = torch.as_tensor(rest_joints, dtype=torch.float64)
    B = len(signals)
    names = [pair_name(j, t) for j, t in pairs]
    parts = []
    for hand, idx, tg, res in solve_in_groups(rest, targets, [FREE_HAND.get(s) for s in signals], pairs, "wrist", **kw):
        if hand is not None:
            grip = dict(pairs).get(f"{hand}_wrist")  # None: the bike has no such grip (nothing to release)
            la = res.local_aa.clone()
            for s in sorted({signals[b] for b in idx}):
                rows = [k for k, b in enumerate(idx) if signals[b] == s]
                sub = la[rows]
                pose_arm(rest, sub, res.root_trans[rows], s)
                la[rows] = sub
            joints, _ = forward_kinematics(rest, rodrigues(la.double()), res.root_trans.double())
            res.local_aa, res.joints = la, joints.to(res.joints.dtype)
            if grip is not None:  # the released hand: how far its wrist is from its grip (reported, never flagged)
                n = pair_name(f"{hand}_wrist", grip)
                tgt = tg[grip].to(torch.float64).reshape(-1, 3).expand(len(idx), 3)
                res.residuals[n] = torch.linalg.vector_norm(joints[:, JOINT_INDEX[f"{hand}_wrist"]] - tgt, dim=-1).float()
                res.flagged[n] = torch.zeros(len(idx), dtype=torch.bool)
        free_name = None if hand is None else pair_name(f"{hand}_wrist", dict(pairs).get(f"{hand}_wrist", ""))
        parts.append((idx, released(res, names, free_name)))
    return merge_results(B, parts, names=names)


def solve_in_groups(rest, targets, sides, pairs, joint, **kw):
    """ik.solve for B frames grouped by sides[b] ("left", "right" or None), each group without the
    pair of its side's `joint` ("wrist": a released hand, "ankle": a foot off its pedal; None: every
    pair held) -> (side, frame indices, the group's targets, IKResult) per group, in first-seen order."""
    B = len(sides)
    groups = {}
    for b, side in enumerate(sides):
        groups.setdefault(side, []).append(b)
    for side, idx in groups.items():
        held = tuple(p for p in pairs if side is None or p[0] != f"{side}_{joint}")
        tg = {k: (v[idx] if torch.is_tensor(v) and v.dim() == 2 and v.shape[0] == B else v) for k, v in targets.items()}
        yield side, idx, tg, solve(rest, tg, pairs=held, **kw)


def merge_results(B, parts, names=None):
    """IKResults of disjoint frame subsets [(frame indices, IKResult), ...] -> one IKResult over B
    frames in order: its residuals, flags and `free` under `names` (default: the first part's), a
    shorter history padded with its last loss, and `ground_gap_m` where a part has one (a batch
    where some frames have a foot down and others an arm signal: foot_down.py)."""
    first = parts[0][1]

    def empty(t):
        return None if t is None else torch.zeros((B,) + tuple(t.shape[1:]), dtype=t.dtype)

    out = {k: empty(getattr(first, k)) for k in ("local_aa", "root_trans", "joints", "loss", "seat_offset", "seat")}
    names = list(first.residuals) if names is None else list(names)
    resid = {n: torch.zeros(B, dtype=torch.float32) for n in names}
    flagged = {n: torch.zeros(B, dtype=torch.bool) for n in names}
    free = {n: torch.zeros(B, dtype=torch.bool) for n in names}
    gaps = any(getattr(r, "ground_gap_m", None) is not None for _, r in parts)
    gap = torch.zeros(B, dtype=torch.float32)
    iters = max(r.history.shape[0] for _, r in parts)
    history = torch.zeros(iters, B, dtype=first.history.dtype)
    for idx, r in parts:
        ix = torch.as_tensor(idx)
        for k, v in out.items():
            if v is not None:
                v[ix] = getattr(r, k).to(v.dtype)
        for n in names:
            resid[n][ix] = r.residuals[n].to(torch.float32)
            flagged[n][ix] = r.flagged[n]
            if r.free is not None:
                free[n][ix] = r.free[n]
        if getattr(r, "ground_gap_m", None) is not None:
            gap[ix] = r.ground_gap_m
        h = r.history
        history[:, ix] = torch.cat([h, h[-1:].expand(iters - h.shape[0], -1)]) if h.shape[0] < iters else h
    res = type(first)(local_aa=out["local_aa"], root_trans=out["root_trans"], joints=out["joints"], loss=out["loss"],
                      residuals=resid, flagged=flagged, seat_offset=out["seat_offset"], history=history,
                      threshold_m=first.threshold_m, seat=out["seat"], free=free)
    if gaps:
        res.ground_gap_m = gap
    return res


def released(res, names, free_name):
    """res with `free` marking the pair free_name (a released hand or foot; None: none) among names."""
    res.free = {n: torch.full((len(res.loss),), n == free_name, dtype=torch.bool) for n in names}
    return res

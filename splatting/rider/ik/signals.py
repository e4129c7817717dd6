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
from splatting.rider.ik.solver import IKResult, solve
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
    groups = {}
    for b, s in enumerate(signals):
        groups.setdefault(FREE_HAND.get(s), []).append(b)
    parts = []
    for hand, idx in groups.items():
        held = tuple(p for p in pairs if hand is None or p[0] != f"{hand}_wrist")
        tg = {k: (v[idx] if torch.is_tensor(v) and v.dim() == 2 and v.shape[0] == B else v) for k, v in targets.items()}
        res = solve(rest, tg, pairs=held, **kw)
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
        parts.append((idx, None if hand is None else pair_name(f"{hand}_wrist", dict(pairs).get(f"{hand}_wrist", "")), res))
    return _merge(parts, B, pairs)


def _merge(parts, B, pairs):
    first = parts[0][2]
    out = {}
    for name in ("local_aa", "root_trans", "joints", "loss"):
        ref = getattr(first, name)
        out[name] = torch.zeros((B,) + tuple(ref.shape[1:]), dtype=ref.dtype)
    seat_off = None if first.seat_offset is None else torch.zeros(B, dtype=first.seat_offset.dtype)
    seat = None if first.seat is None else torch.zeros(B, 3, dtype=first.seat.dtype)
    names = [pair_name(j, t) for j, t in pairs]
    resid = {n: torch.zeros(B, dtype=torch.float32) for n in names}
    flagged = {n: torch.zeros(B, dtype=torch.bool) for n in names}
    free = {n: torch.zeros(B, dtype=torch.bool) for n in names}
    iters = max(r.history.shape[0] for _, _, r in parts)
    history = torch.zeros(iters, B, dtype=first.history.dtype)
    for idx, free_name, r in parts:
        ix = torch.tensor(idx)
        for name in ("local_aa", "root_trans", "joints", "loss"):
            out[name][ix] = getattr(r, name).to(out[name].dtype)
        if seat_off is not None:
            seat_off[ix] = r.seat_offset.to(seat_off.dtype)
        if seat is not None:
            seat[ix] = r.seat.to(seat.dtype)
        h = r.history
        history[:, ix] = torch.cat([h, h[-1:].expand(iters - h.shape[0], -1)]) if h.shape[0] < iters else h
        for (j, t), n in zip(pairs, names):
            resid[n][ix] = r.residuals[n].to(torch.float32)
            flagged[n][ix] = r.flagged[n]
            free[n][ix] = n == free_name
    return IKResult(local_aa=out["local_aa"], root_trans=out["root_trans"], joints=out["joints"], loss=out["loss"],
                    residuals=resid, flagged=flagged, seat_offset=seat_off, history=history,
                    threshold_m=first.threshold_m, seat=seat, free=free)

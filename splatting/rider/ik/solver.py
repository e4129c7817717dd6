"""The batched IK solve: hand-written Adam on one flat parameter tensor (11 joints + root
orientation, root translation, seat offset), hinge projection, keep-best per frame."""
import math
from dataclasses import dataclass

import torch

from cyclist_formats.errors import UserError
from splatting.rider.ik.chain import ReducedChain
from splatting.rider.ik.slots import (DEFAULT_PAIRS, EXACT_START_M, FLAG_THRESHOLD_M, HINGE_MAX_RAD, HINGE_SLOTS, N_ROT,
                                      OBJECTIVES, PELVIS_ABOVE_SEAT_M, SEAT_RANGE_M, SLOT_JOINTS, hinge_axes,
                                      pair_name)
from splatting.rider.ik.start import analytic_init_pose, cycling_init_pose, saddle_offset_for_reach
from splatting.rider.ik.targets import batch_of, finite_tensor, prepare_targets
from splatting.rider.kinematics import JOINT_INDEX, forward_kinematics
from splatting.rotations import rodrigues


@dataclass
class IKResult:
    local_aa: torch.Tensor      # (B, 24, 3) axis-angle local rotations (joint 0 = root orientation)
    root_trans: torch.Tensor    # (B, 3) for kinematics.forward_kinematics
    joints: torch.Tensor        # (B, 24, 3) posed joints
    loss: torch.Tensor          # (B,) loss at the kept iteration
    residuals: dict             # "joint->target" -> (B,) metres
    flagged: dict               # "joint->target" -> (B,) bool, residual > threshold_m
    seat_offset: torch.Tensor   # (B,) metres along crank_axle->seat, or None without saddle fit
    history: torch.Tensor       # (iterations, B) loss at every iteration
    threshold_m: float
    seat: torch.Tensor = None   # (B, 3) the (fitted) seat position, or None without a seat pair
    free: dict = None           # "joint->target" -> (B,) bool: a hand released for an arm signal (ik/signals.py)


def solve(rest_joints, targets, init_local_aa=None, init_root=None, objective="pairs", iterations=50,
          lr=0.05, saddle_fit=False, saddle_shared=False, pairs=DEFAULT_PAIRS,
          pelvis_above_seat_m=PELVIS_ABOVE_SEAT_M, up=(0.0, 1.0, 0.0), seat_range_m=SEAT_RANGE_M,
          flag_threshold_m=FLAG_THRESHOLD_M, w_hinge=1.0, w_off_hinge=1e-2, w_prior=1e-4, w_seat=1e-3,
          betas=(0.9, 0.999), pair_weights=None, init="analytic", exact_start_m=EXACT_START_M):
    """Batched keypoint IK for B frames.

    rest_joints (24, 3) metres, canonical frame; targets: name -> (B, 3) or (3,) world positions
    for every target of `pairs` (plus `crank_axle` with saddle_fit); init_local_aa (B, 24, 3) or
    (24, 3) (default: cycling_init_pose); init_root (B, 3) root translation (default: the pelvis on
    its target).  `up` (3,) or (B, 3) is the bike's up direction for the pelvis-above-seat offset.
    saddle_fit slides the seat (and the pelvis target) along crank_axle -> seat within
    seat_range_m; saddle_shared uses one offset for all B frames (one seat post for a sequence).
    exact_start_m: when the start already puts every pair within this distance (m) in every frame,
    it is returned without Adam (history then has one row); None always runs all iterations.
    Returns IKResult.  Bad input (NaN/Inf, missing targets, wrong shapes) raises UserError.
    """
    if objective not in OBJECTIVES:
        raise UserError(f"ik: objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    if init not in ("analytic", "generic"):
        raise UserError(f"ik: init must be 'analytic' or 'generic', got {init!r}")
    if not isinstance(iterations, int) or iterations < 1:
        raise UserError(f"ik: iterations must be a positive integer, got {iterations!r}")
    for name, v in (("lr", lr), ("pelvis_above_seat_m", pelvis_above_seat_m), ("flag_threshold_m", flag_threshold_m)):
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise UserError(f"ik: {name} must be a finite number, got {v!r}")
    pairs = tuple((str(j), str(t)) for j, t in pairs)
    bad = [j for j, _ in pairs if j not in JOINT_INDEX]
    if bad or not pairs:
        raise UserError(f"ik: pairs need SMPL joint names, got {bad or 'no pairs'}")
    rest = finite_tensor(rest_joints, "rest_joints", (24, 3))
    if rest.dim() != 2:
        raise UserError(f"ik: rest_joints must be (24, 3), got {tuple(rest.shape)}")
    hint = 1
    if init_local_aa is not None:
        init_aa = finite_tensor(init_local_aa, "init_local_aa", (24, 3))
        hint = batch_of(init_aa, 2)
    if init_root is not None:
        init_root_t = finite_tensor(init_root, "init_root", (3,))
        hint = max(hint, batch_of(init_root_t, 1))
    names = [t for _, t in pairs] + (["crank_axle"] if saddle_fit else [])
    tg, B = prepare_targets(targets, list(dict.fromkeys(names)), hint)
    up_t = finite_tensor(up, "up", (3,)).reshape(-1, 3).expand(B, 3)
    up_t = up_t / torch.linalg.vector_norm(up_t, dim=-1, keepdim=True).clamp_min(1e-9)

    slot_idx = [JOINT_INDEX[n] for n in SLOT_JOINTS]
    seat_i = [k for k, (_, t) in enumerate(pairs) if t == "seat"]
    pelvis_lift = torch.zeros(B, len(pairs), 3, dtype=torch.float64)
    for k, (j, t) in enumerate(pairs):
        if j == "pelvis" and t == "seat":
            pelvis_lift[:, k] = pelvis_above_seat_m * up_t
    T0 = torch.stack([tg[t] for _, t in pairs], 1) + pelvis_lift  # (B, P, 3)
    U = torch.zeros(B, len(pairs), 3, dtype=torch.float64)  # where the saddle offset moves targets
    s0 = torch.zeros(B, dtype=torch.float64)
    lo, hi = (float(x) for x in seat_range_m)
    if saddle_fit:
        if not seat_i:
            raise UserError("ik: saddle_fit needs a pair with the 'seat' target")
        if not lo <= 0.0 <= hi:
            raise UserError(f"ik: seat_range_m must contain 0, got {seat_range_m!r}")
        tube = tg["seat"] - tg["crank_axle"]
        n = torch.linalg.vector_norm(tube, dim=-1, keepdim=True)
        if not (n > 1e-3).all():
            raise UserError("ik: saddle_fit: seat and crank_axle coincide")
        U[:, seat_i] = (tube / n)[:, None]
        s0 = saddle_offset_for_reach(rest, T0, U, pairs, lo, hi)
        if saddle_shared:
            s0 = s0.min().expand(B)
    T_init = T0 + s0[:, None, None] * U
    pj = [k for k, (j, _) in enumerate(pairs) if j == "pelvis"]
    # the pelvis joint on its target (or over the mean target when it has none)
    root0 = (T_init[:, pj[0]] if pj else T_init.mean(1)) - rest[0]
    if init_local_aa is not None:
        init_aa = init_aa.reshape(-1, 24, 3).expand(B, 24, 3)
    elif init == "analytic":
        init_aa, _ = analytic_init_pose(rest, {t: T_init[:, k] for k, (_, t) in enumerate(pairs)}, pairs)
    else:
        init_aa = torch.as_tensor(cycling_init_pose(rest.numpy())).expand(B, 24, 3)
    if init_root is not None:
        root0 = init_root_t.reshape(-1, 3).expand(B, 3)
    init_R = rodrigues(init_aa)

    f32 = torch.float32
    chain = ReducedChain(rest, init_R, [j for j, _ in pairs])
    axes = hinge_axes(rest).to(f32)
    T0, U = T0.to(f32), U.to(f32)
    P0 = torch.cat([init_aa[:, slot_idx].reshape(B, N_ROT), root0, s0[:, None]], 1).to(f32)
    prior_w = torch.zeros(P0.shape[1], dtype=f32)
    prior_w[:N_ROT] = w_prior
    if saddle_fit:
        prior_w[-1] = w_seat
    pw = torch.ones(len(pairs), dtype=f32)
    if pair_weights is not None:
        pw = finite_tensor(pair_weights, "pair_weights", (len(pairs),)).to(f32)
    chamfer = objective == "chamfer"

    def loss_fn(P):
        rot = rodrigues(P[:, :N_ROT].view(B, len(SLOT_JOINTS), 3))
        eff = chain(rot, P[:, N_ROT:N_ROT + 3])
        tgt = T0 + P[:, -1:, None] * U if saddle_fit else T0
        if chamfer:
            d2 = ((eff[:, :, None] - tgt[:, None]) ** 2).sum(-1)
            fit = 0.5 * (d2.min(2).values.sum(1) + d2.min(1).values.sum(1))
        else:
            fit = (((eff - tgt) ** 2).sum(2) * pw).sum(1)
        h = P[:, 3 * HINGE_SLOTS.start:3 * HINGE_SLOTS.stop].view(B, 4, 3)
        theta = (h * axes).sum(-1)
        off = h - theta[..., None] * axes
        hinge = w_hinge * torch.relu(theta - HINGE_MAX_RAD).square().sum(1) + w_off_hinge * off.square().sum((1, 2))
        prior = ((P - P0).square() * prior_w).sum(1)
        return fit + hinge + prior

    hs = slice(3 * HINGE_SLOTS.start, 3 * HINGE_SLOTS.stop)

    def project(P):  # in place: hinges never bend backwards; the seat post stays within its travel
        h = P[:, hs].view(B, 4, 3)
        h -= torch.clamp((h * axes).sum(-1), max=0.0)[..., None] * axes
        if saddle_fit:
            P[:, -1].clamp_(lo, hi)

    project(P0)  # a given initial pose may bend a knee backwards
    if exact_start_m is not None:
        # From an exact start Adam's first steps only move away (every parameter by ~lr) and the
        # keep-best rule returns the start anyway; skipping them is ~90 % of a dataset image's IK.
        with torch.no_grad():
            eff = chain(rodrigues(P0[:, :N_ROT].view(B, len(SLOT_JOINTS), 3)), P0[:, N_ROT:N_ROT + 3])
            tgt = T0 + P0[:, -1:, None] * U if saddle_fit else T0
            if float(torch.linalg.vector_norm(eff - tgt, dim=-1).max()) <= exact_start_m:
                loss0 = loss_fn(P0)
                return _result(rest, init_aa, P0, loss0, loss0[None], pairs, tg, T0, U, saddle_fit,
                               flag_threshold_m, slot_idx, seat_i, pelvis_lift)
    P = P0.clone().requires_grad_(True)
    m, v = torch.zeros_like(P0), torch.zeros_like(P0)
    best_loss = torch.full((B,), float("inf"), dtype=f32)
    best_P = P0.clone()
    history = torch.empty(iterations, B, dtype=f32)
    b1, b2 = betas
    for it in range(iterations):
        loss = loss_fn(P)
        (g,) = torch.autograd.grad(loss.sum(), P)
        with torch.no_grad():
            history[it] = loss
            better = (loss < best_loss) if not (saddle_fit and saddle_shared) else (loss.sum() < best_loss.sum()).expand(B)
            best_loss = torch.where(better, loss, best_loss)
            best_P = torch.where(better[:, None], P, best_P)
            if it == iterations - 1:
                break
            if saddle_fit and saddle_shared:
                g[:, -1] = g[:, -1].mean()
            m.mul_(b1).add_(g, alpha=1 - b1)
            v.mul_(b2).addcmul_(g, g, value=1 - b2)
            t = it + 1
            denom = (v / (1 - b2 ** t)).sqrt_().add_(1e-8)
            P.addcdiv_(m, denom, value=-lr / (1 - b1 ** t))
            project(P)
    return _result(rest, init_aa, best_P, best_loss, history, pairs, tg, T0, U, saddle_fit, flag_threshold_m,
                   slot_idx, seat_i, pelvis_lift)


def _result(rest, init_aa, P, loss, history, pairs, tg, T0, U, saddle_fit, threshold, slot_idx, seat_i, lift):
    B = P.shape[0]
    local_aa = init_aa.to(torch.float32).clone()
    local_aa[:, slot_idx] = P[:, :N_ROT].view(B, len(SLOT_JOINTS), 3)
    trans = P[:, N_ROT:N_ROT + 3].clone()
    joints, _ = forward_kinematics(rest.to(torch.float32), rodrigues(local_aa), trans)
    s = P[:, -1].clone() if saddle_fit else None
    tgt = T0 + P[:, -1, None, None] * U if saddle_fit else T0
    residuals, flagged = {}, {}
    for k, (j, t) in enumerate(pairs):
        r = torch.linalg.vector_norm(joints[:, JOINT_INDEX[j]] - tgt[:, k], dim=-1)
        residuals[pair_name(j, t)] = r
        flagged[pair_name(j, t)] = r > threshold
    seat = None
    if "seat" in tg:
        seat = tg["seat"].to(torch.float32) + (s[:, None] * (U[:, seat_i[0]]) if saddle_fit else 0.0)
    return IKResult(local_aa=local_aa, root_trans=trans, joints=joints, loss=loss, residuals=residuals,
                    flagged=flagged, seat_offset=s, history=history, threshold_m=float(threshold), seat=seat)

"""The batched IK solve: hand-written Adam on one flat parameter tensor (11 joints + root
orientation, root translation, seat offset), hinge projection, keep-best per frame, and more
steps only for the frames not yet converged."""
import math
from dataclasses import dataclass

import torch

from cyclist_formats.errors import UserError
from splatting.rider.ik.chain import ReducedChain
from splatting.rider.ik.slots import (CHECK_EVERY, CONVERGED_M, DEFAULT_PAIRS, EXACT_START_M, EXTEND_FACTOR,
                                      FLAG_THRESHOLD_M, HINGE_MAX_RAD, HINGE_SLOTS, MIN_GAIN, N_ROT, OBJECTIVES,
                                      PELVIS_ABOVE_SEAT_M, SEAT_RANGE_M, SLOT_JOINTS, hinge_axes, pair_name)
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
    history: torch.Tensor       # (steps run, B) loss at every iteration (solve: continuation)
    threshold_m: float
    seat: torch.Tensor = None   # (B, 3) the (fitted) seat position, or None without a seat pair
    free: dict = None           # "joint->target" -> (B,) bool: a hand released for an arm signal (ik/signals.py)


def solve(rest_joints, targets, init_local_aa=None, init_root=None, objective="pairs", iterations=50,
          lr=0.05, saddle_fit=False, saddle_shared=False, pairs=DEFAULT_PAIRS,
          pelvis_above_seat_m=PELVIS_ABOVE_SEAT_M, up=(0.0, 1.0, 0.0), seat_range_m=SEAT_RANGE_M,
          flag_threshold_m=FLAG_THRESHOLD_M, w_hinge=1.0, w_off_hinge=1e-2, w_prior=1e-4, w_seat=1e-3,
          betas=(0.9, 0.999), pair_weights=None, init="analytic", exact_start_m=EXACT_START_M, max_iterations=None,
          converge_m=CONVERGED_M, check_every=CHECK_EVERY, min_gain=MIN_GAIN):
    """Batched keypoint IK for B frames.

    rest_joints (24, 3) metres, canonical frame; targets: name -> (B, 3) or (3,) world positions
    for every target of `pairs` (plus `crank_axle` with saddle_fit); init_local_aa (B, 24, 3) or
    (24, 3) (default: cycling_init_pose); init_root (B, 3) root translation (default: the pelvis on
    its target).  `up` (3,) or (B, 3) is the bike's up direction for the pelvis-above-seat offset.
    saddle_fit slides the seat (and the pelvis target) along crank_axle -> seat within
    seat_range_m; saddle_shared uses one offset for all B frames (one seat post for a sequence).
    exact_start_m: when the start already puts every pair within this distance (m) in every frame,
    it is returned without Adam (history then has one row); None always runs all iterations.
    Continuation: after `iterations` steps, frames whose worst pair (of those with weight) is still
    farther than converge_m (m) go on check_every steps at a time while their kept loss drops by at
    least min_gain (a fraction) per check, up to max_iterations in all (default EXTEND_FACTOR x
    iterations; max_iterations=iterations: exactly `iterations` steps).  Frames within converge_m
    after `iterations` steps are bit-identical to a plain `iterations`-step solve; with
    saddle_shared the whole batch goes on together (one seat post).  history then has a row per
    step the longest frame ran, a stopped frame's last loss repeated.
    Returns IKResult.  Bad input (NaN/Inf, missing targets, wrong shapes) raises UserError.
    """
    if objective not in OBJECTIVES:
        raise UserError(f"ik: objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    if init not in ("analytic", "generic"):
        raise UserError(f"ik: init must be 'analytic' or 'generic', got {init!r}")
    if not isinstance(iterations, int) or iterations < 1:
        raise UserError(f"ik: iterations must be a positive integer, got {iterations!r}")
    cap = EXTEND_FACTOR * iterations if max_iterations is None else max_iterations
    if not isinstance(cap, int) or isinstance(cap, bool) or cap < iterations:
        raise UserError(f"ik: max_iterations must be an integer >= iterations ({iterations}), got {max_iterations!r}")
    if not isinstance(check_every, int) or isinstance(check_every, bool) or check_every < 1:
        raise UserError(f"ik: check_every must be a positive integer, got {check_every!r}")
    for name, v in (("lr", lr), ("pelvis_above_seat_m", pelvis_above_seat_m), ("flag_threshold_m", flag_threshold_m),
                    ("converge_m", converge_m), ("min_gain", min_gain)):
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise UserError(f"ik: {name} must be a finite number, got {v!r}")
    if converge_m < 0 or not 0 <= min_gain < 1:
        raise UserError(f"ik: converge_m must be >= 0 and min_gain in [0, 1), got {converge_m!r}, {min_gain!r}")
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
    if not (pw > 0).any():
        cap = iterations  # no pair counts: nothing to converge

    def make_loss(ix):  # the loss over the batch rows ix (None: all of them)
        T0x, Ux, P0x = (T0, U, P0) if ix is None else (T0[ix], U[ix], P0[ix])
        chainx = chain if ix is None else chain.rows(ix)

        def loss_fn(P):
            Bx = P.shape[0]
            rot = rodrigues(P[:, :N_ROT].view(Bx, len(SLOT_JOINTS), 3))
            eff = chainx(rot, P[:, N_ROT:N_ROT + 3])
            tgt = T0x + P[:, -1:, None] * Ux if saddle_fit else T0x
            if chamfer:
                d2 = ((eff[:, :, None] - tgt[:, None]) ** 2).sum(-1)
                fit = 0.5 * (d2.min(2).values.sum(1) + d2.min(1).values.sum(1))
            else:
                fit = (((eff - tgt) ** 2).sum(2) * pw).sum(1)
            h = P[:, 3 * HINGE_SLOTS.start:3 * HINGE_SLOTS.stop].view(Bx, 4, 3)
            theta = (h * axes).sum(-1)
            off = h - theta[..., None] * axes
            hinge = w_hinge * torch.relu(theta - HINGE_MAX_RAD).square().sum(1) + w_off_hinge * off.square().sum((1, 2))
            prior = ((P - P0x).square() * prior_w).sum(1)
            return fit + hinge + prior

        def worst_m(P):  # per row, the farthest pair (of those with weight) at P, metres
            eff = chainx(rodrigues(P[:, :N_ROT].view(P.shape[0], len(SLOT_JOINTS), 3)), P[:, N_ROT:N_ROT + 3])
            tgt = T0x + P[:, -1:, None] * Ux if saddle_fit else T0x
            return torch.linalg.vector_norm(eff - tgt, dim=-1)[:, pw > 0].max(1).values

        return loss_fn, worst_m

    loss_fn, _ = make_loss(None)
    hs = slice(3 * HINGE_SLOTS.start, 3 * HINGE_SLOTS.stop)

    def project(P):  # in place: hinges never bend backwards; the seat post stays within its travel
        h = P[:, hs].view(P.shape[0], 4, 3)
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
    shared = saddle_fit and saddle_shared
    # full-batch Adam state; a continuation works on the rows still running and writes them back
    S = dict(P=P0.clone(), m=torch.zeros_like(P0), v=torch.zeros_like(P0), g=torch.zeros_like(P0),
             best_loss=torch.full((B,), float("inf"), dtype=f32), best_P=P0.clone())
    history = torch.empty(cap, B, dtype=f32)
    last_it = torch.full((B,), iterations - 1, dtype=torch.long)  # each row's last iteration run
    b1, b2 = betas

    def run(ix, start, stop, loss_fn):
        """Iterations start..stop-1 on rows ix: Adam's step from the previous gradient, then the loss
        at the new point (as one loop of `iterations` steps would do them)."""
        st = S if ix is None else {k: t[ix] for k, t in S.items()}
        P = st["P"].requires_grad_(True)
        m, v, g, best_loss, best_P = st["m"], st["v"], st["g"], st["best_loss"], st["best_P"]
        for it in range(start, stop):
            if it > 0:
                with torch.no_grad():
                    m.mul_(b1).add_(g, alpha=1 - b1)
                    v.mul_(b2).addcmul_(g, g, value=1 - b2)
                    denom = (v / (1 - b2 ** it)).sqrt_().add_(1e-8)
                    P.addcdiv_(m, denom, value=-lr / (1 - b1 ** it))
                    project(P)
            loss = loss_fn(P)
            (g,) = torch.autograd.grad(loss.sum(), P)
            with torch.no_grad():
                if shared:
                    g[:, -1] = g[:, -1].mean()
                if ix is None:
                    history[it] = loss
                else:
                    history[it, ix] = loss
                better = loss < best_loss if not shared else (loss.sum() < best_loss.sum()).expand(loss.shape[0])
                best_loss = torch.where(better, loss, best_loss)
                best_P = torch.where(better[:, None], P, best_P)
        out = dict(P=P.detach(), m=m, v=v, g=g, best_loss=best_loss, best_P=best_P)
        for k, t in out.items():
            if ix is None:
                S[k] = t
            else:
                S[k][ix] = t

    run(None, 0, iterations, loss_fn)
    # Continue the frames not yet converged (see CONVERGED_M): frames that are stay bit-identical to
    # a plain `iterations`-step solve; with one shared seat post the whole batch goes on together.
    active = torch.arange(B)
    done, prev_best = iterations, None
    while done < cap and len(active):
        ix = None if len(active) == B else active
        loss_x, worst_x = make_loss(ix)
        with torch.no_grad():
            best_P = S["best_P"] if ix is None else S["best_P"][ix]
            best_loss = S["best_loss"] if ix is None else S["best_loss"][ix]
            go = worst_x(best_P) > converge_m
            if prev_best is not None:  # still gaining?
                gain = (best_loss.sum() < (1 - min_gain) * prev_best.sum()).expand_as(go) if shared \
                    else best_loss < (1 - min_gain) * prev_best
                go &= gain
            if shared:
                go = go.any().expand_as(go)
        if not go.any():
            break
        prev_best = best_loss[go]
        if not go.all():  # fewer rows: their own loss closure
            active = active[go]
            ix = active
            loss_x, _ = make_loss(ix)
        stop = min(done + check_every, cap)
        run(ix, done, stop, loss_x)
        last_it[active] = stop - 1
        done = stop
    # rows that stopped early: their last loss repeated (as combined results pad a shorter history)
    history = history[:done]
    history = torch.where(torch.arange(done)[:, None] > last_it, history.gather(0, last_it[None]), history)
    best_P, best_loss = S["best_P"], S["best_loss"]
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

"""Keypoint inverse kinematics: hands on the handles, pelvis on the saddle, feet on the pedals.

The paper refines 11 joint rotations (spine1, shoulders, elbows, hips, knees, ankles) with Adam
(lr 0.05, 50 iterations) so that rider keypoints meet bike keypoints.  Here B frames are solved at
once; besides the 11 joints the root orientation and translation are free (the pelvis cannot reach
the saddle otherwise), and an optional saddle offset slides the seat along the seat tube.

Objectives (per frame, squared metres):
  pairs    sum over pairs of |joint - target|^2 (default pairs: DEFAULT_PAIRS)
  chamfer  the paper's symmetric Chamfer between the rider's and the bike's keypoint sets,
           0.5 * (sum_i min_j d_ij^2 + sum_j min_i d_ij^2), so it equals `pairs` when matched.
Priors: knees and elbows are hinges.  Their hinge angle theta = aa . axis (axis from the rest
skeleton, positive = flexion) is projected onto theta >= 0 after every step (they can never bend
backwards), penalised above HINGE_MAX_RAD, and the off-hinge part of their rotation is penalised;
a small quadratic prior pulls all free rotations toward the initial pose; a tiny one pulls the
saddle offset toward 0 so the seat only moves when the legs need it.
Per frame the iteration with the lowest loss is kept.  Residuals are distances (m) between each
pair's joint and target at that iteration; a pair is flagged unreachable above `flag_threshold_m`.

Speed: only the kinematic chain that reaches the end-effectors is built, with constant joints
between two free ones folded into one precomputed rotation and offset, and processed level by
level (left and right limbs in one batched matmul); Adam is hand-written on one flat parameter
tensor.  See docs/ik.md for measured numbers.
"""
import math
from dataclasses import dataclass

import numpy as np
import roma
import torch

from cyclist_formats.errors import UserError
from splatting.rider.kinematics import JOINT_INDEX, JOINT_NAMES, PARENTS, forward_kinematics
from splatting.rotations import rodrigues, rotmat_to_axis_angle as _rotmat_to_aa  # noqa: F401

IK_JOINTS = ("spine1", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_hip",
             "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")
DEFAULT_PAIRS = (("left_wrist", "handle_left"), ("right_wrist", "handle_right"), ("pelvis", "seat"),
                 ("left_ankle", "pedal_left"), ("right_ankle", "pedal_right"))
# hinge joint -> direction (canonical frame) its child segment swings toward when it flexes
HINGE_FLEX_DIRECTION = {"left_knee": (-1.0, 0.0, 0.0), "right_knee": (-1.0, 0.0, 0.0),
                        "left_elbow": (1.0, 0.0, 0.0), "right_elbow": (1.0, 0.0, 0.0)}
HINGE_MAX_RAD = math.radians(150.0)
PELVIS_ABOVE_SEAT_M = 0.09  # the SMPL pelvis joint sits ~9 cm above the saddle top when seated
SEAT_RANGE_M = (-0.15, 0.05)  # saddle auto-fit: seat-post travel along the seat tube
FLAG_THRESHOLD_M = 0.03
OBJECTIVES = ("pairs", "chamfer")

# parameter slots: root orientation, then the 11 joints with the four hinges last (one slice)
SLOT_JOINTS = ("pelvis", "spine1", "left_shoulder", "right_shoulder", "left_hip", "right_hip",
                "left_ankle", "right_ankle", "left_elbow", "right_elbow", "left_knee", "right_knee")
_HINGE_SLOTS = slice(8, 12)
_N_ROT = len(SLOT_JOINTS) * 3  # 36 rotation columns, then 3 translation, then 1 seat offset


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


def pair_name(joint, target):
    return f"{joint}->{target}"


# ------------------------------------------------------------------ small helpers

def hinge_axes(rest_joints):
    """Unit flexion axes (4, 3) of the hinge slots (knees, elbows) in the rest frame: positive
    rotation about it swings the child segment toward HINGE_FLEX_DIRECTION."""
    rest = torch.as_tensor(rest_joints, dtype=torch.float64)
    axes = []
    for name in SLOT_JOINTS[_HINGE_SLOTS]:
        j = JOINT_INDEX[name]
        u = rest[j] - rest[PARENTS[j]]  # the parent segment (thigh, upper arm) in the rest pose
        a = torch.linalg.cross(u, torch.tensor(HINGE_FLEX_DIRECTION[name], dtype=torch.float64))
        n = torch.linalg.vector_norm(a)
        if not n > 1e-6:
            raise UserError(f"rest skeleton: {name}'s parent segment is parallel to its flexion direction")
        axes.append(a / n)
    return torch.stack(axes)


def _align(u, d):
    """Axis-angle of the smallest rotation taking direction u to direction d (numpy)."""
    u, d = u / np.linalg.norm(u), d / np.linalg.norm(d)
    ax = np.cross(u, d)
    s, c = np.linalg.norm(ax), float(np.dot(u, d))
    return ax / s * math.atan2(s, c) if s > 1e-9 else np.zeros(3)


def cycling_init_pose(rest_joints):
    """(24, 3) axis-angle: a generic seated pedalling pose for this rest skeleton (torso leaning
    ~30 deg forward, thighs forward, knees and elbows bent), the default IK start.  Bent hinges
    matter: at a straight knee the gradient along the leg vanishes."""
    rest = np.asarray(rest_joints, dtype=np.float64)
    axes = hinge_axes(rest).numpy()
    aa = np.zeros((24, 3))
    lean = np.array([0.0, 0.0, -math.radians(30)])  # about -Z: the torso tips toward +X
    aa[JOINT_INDEX["spine1"]] = lean
    R_lean = roma.rotvec_to_rotmat(torch.tensor(lean)).numpy()
    for side, sz in (("left", -1.0), ("right", 1.0)):
        hip, knee = JOINT_INDEX[f"{side}_hip"], JOINT_INDEX[f"{side}_knee"]
        aa[hip] = _align(rest[knee] - rest[hip], np.array([0.55, -0.83, 0.0]))  # thigh ~56 deg up
        aa[knee] = axes[SLOT_JOINTS[_HINGE_SLOTS].index(f"{side}_knee")] * 1.4
        sh, el = JOINT_INDEX[f"{side}_shoulder"], JOINT_INDEX[f"{side}_elbow"]
        world = _align(rest[el] - rest[sh], np.array([0.55, -0.8, 0.15 * sz]))
        # local = R_parent^T * world rotation; the parent chain (spine1..collar) carries the lean
        Rw = roma.rotvec_to_rotmat(torch.tensor(world)).numpy()
        aa[sh] = roma.rotmat_to_rotvec(torch.tensor(R_lean.T @ Rw)).numpy()
        aa[el] = axes[SLOT_JOINTS[_HINGE_SLOTS].index(f"{side}_elbow")] * 0.5
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
    aa = torch.as_tensor(cycling_init_pose(rest.numpy())).expand(B, 24, 3).clone()
    of = {j: t for j, t in pairs}
    pelvis = targets[of["pelvis"]] if "pelvis" in of else rest[0].expand(B, 3)
    trans = pelvis - rest[0]
    axes = dict(zip(SLOT_JOINTS[_HINGE_SLOTS], hinge_axes(rest)))
    J = lambda n: rest[JOINT_INDEX[n]]  # noqa: E731
    seg = lambda a, b: float(torch.linalg.vector_norm(J(b) - J(a)))  # noqa: E731
    # torso lean about the lateral axis, from a grid (vectorised over frames)
    hands = [(s, of[f"{s}_wrist"]) for s in ("left", "right") if f"{s}_wrist" in of]
    R_lean = roma.rotvec_to_rotmat(torch.tensor(cycling_init_pose(rest.numpy())[JOINT_INDEX["spine1"]])).expand(B, 3, 3)
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
        aa[:, JOINT_INDEX["spine1"]] = _rotmat_to_aa(R_lean)
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
            aa[:, JOINT_INDEX[a]] = _rotmat_to_aa(R_w if parent_R is None else parent_R.transpose(-1, -2) @ R_w)
            aa[:, JOINT_INDEX[b]] = theta[:, None] * axes[b]
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


def _finite_tensor(x, what, shape_tail, batch=None):
    try:
        t = torch.as_tensor(np.asarray(x, dtype=np.float64) if not torch.is_tensor(x) else x.detach(),
                            dtype=torch.float64)
    except (TypeError, ValueError) as e:
        raise UserError(f"ik: {what} is not numeric: {e}") from None
    if t.shape[-len(shape_tail):] != shape_tail or t.dim() > len(shape_tail) + 1:
        raise UserError(f"ik: {what} must have shape {tuple(shape_tail)} or (B, {', '.join(map(str, shape_tail))}), "
                        f"got {tuple(t.shape)}")
    if not torch.isfinite(t).all():
        raise UserError(f"ik: {what} contains NaN or Inf")
    if batch is not None and t.dim() == len(shape_tail) + 1 and t.shape[0] not in (1, batch):
        raise UserError(f"ik: {what} has {t.shape[0]} frames, expected {batch}")
    return t


def _batch_of(t, tail):
    return t.shape[0] if t.dim() == tail + 1 else 1


# ------------------------------------------------------------------ the reduced kinematic chain

class _Chain:
    """FK over only the joints on a path root -> end-effector, with free rotations from the
    parameter slots and constant joints between two kept joints folded into (C, d):
    R_world[j] = R_world[a] @ C_j @ L_j,  pos[j] = pos[a] + R_world[a] @ d_j  (a = kept ancestor).
    Kept joints are processed by depth, one batched matmul per level."""

    def __init__(self, rest, init_R, effectors):
        B = init_R.shape[0]
        slot = {JOINT_INDEX[n]: i for i, n in enumerate(SLOT_JOINTS)}
        eff = [JOINT_INDEX[n] for n in effectors]

        def ancestors(j):
            out = []
            while PARENTS[j] >= 0:
                j = PARENTS[j]
                out.append(j)
            return out

        anc_of_eff = {a for e in eff for a in ancestors(e)}
        keep = sorted({0} | set(eff) | {j for j in slot if j in anc_of_eff})
        kparent, depth, has_child = {}, {0: 0}, set()
        for j in keep[1:]:
            a = next(x for x in ancestors(j) if x in keep)
            kparent[j], depth[j] = a, depth[a] + 1
            has_child.add(a)
        off = rest.clone()
        off[1:] = rest[1:] - rest[list(PARENTS[1:])]
        eye = torch.eye(3, dtype=rest.dtype).expand(B, 3, 3)
        carried = {0: 0}  # joint -> row in the previous level's carried (R, pos), i.e. joints with kept children
        col, ncols = {0: 0}, 1  # joint -> column in the concatenation of every level's positions
        self.levels = []
        for lev in range(1, max(depth.values(), default=0) + 1):
            nodes = [j for j in keep if depth[j] == lev]
            pidx, Cs, ds, slots, rows = [], [], [], [], []
            for k, j in enumerate(nodes):
                path = [j]
                while PARENTS[path[-1]] != kparent[j]:
                    path.append(PARENTS[path[-1]])
                C, d = eye, torch.zeros(B, 3, dtype=rest.dtype)
                for p in path[::-1]:  # from the kept ancestor's child down to j
                    d = d + (C @ off[p])
                    if p != j:
                        C = C @ init_R[:, p]
                if j in has_child:
                    if j in slot:
                        slots.append(slot[j])
                    else:  # a constant joint with kept children: its rotation goes into C
                        C = C @ init_R[:, j]
                        slots.append(len(SLOT_JOINTS))  # the identity slot
                    rows.append(k)
                    Cs.append(C)
                pidx.append(carried[kparent[j]])
                ds.append(d)
                col[j] = ncols + k
            ncols += len(nodes)
            self.levels.append(dict(
                pidx=torch.tensor(pidx), d=torch.stack(ds, 1)[..., None].float(),
                C=torch.stack(Cs, 1).float() if Cs else None, slots=torch.tensor(slots, dtype=torch.long),
                rows=None if rows == list(range(len(nodes))) else torch.tensor(rows, dtype=torch.long),
                carry=bool(rows)))
            carried = {nodes[k]: r for r, k in enumerate(rows)}
        self.rest_root = rest[0].float()
        self.needs_identity = any(L["carry"] and int(L["slots"].max()) == len(SLOT_JOINTS) for L in self.levels)
        self.eff_cols = torch.tensor([col[j] for j in eff])

    def __call__(self, rot, trans):
        """rot (B, 12, 3, 3) slot rotations, trans (B, 3) -> effector positions (B, E, 3)."""
        if self.needs_identity:
            rot = torch.cat([rot, torch.eye(3, dtype=rot.dtype).expand(rot.shape[0], 1, 3, 3)], 1)
        Rw = rot[:, :1]  # the root's world rotation (B, 1, 3, 3)
        pos = (self.rest_root + trans)[:, None]  # the root rotates about itself
        all_pos = [pos]
        for L in self.levels:
            Rp = Rw[:, L["pidx"]]
            pos = pos[:, L["pidx"]] + (Rp @ L["d"])[..., 0]
            all_pos.append(pos)
            if L["carry"]:
                if L["rows"] is not None:
                    Rp, pos = Rp[:, L["rows"]], pos[:, L["rows"]]
                Rw = Rp @ (L["C"] @ rot[:, L["slots"]])
        return torch.cat(all_pos, 1)[:, self.eff_cols]


def posed_bike_keypoints(keypoints, poses_deg):
    """Bike keypoints {name: (3,)} (canonical, rest) at B 8-DoF poses (docs/contract.md, degrees and
    metres) -> {name: (B, 3) float64}: steering keypoints turn with theta_s, pedals with theta_p,
    then the global transform.  What the IK needs without loading a BikeModel's Gaussians."""
    from cyclist_formats.bike_folder import DEFAULT_KEYPOINT_PARTS
    from splatting.bike.pose import pose_transforms, transform_points

    kp = {k: torch.as_tensor(v, dtype=torch.float64) for k, v in keypoints.items()}
    H = pose_transforms(poses_deg, kp["steer_bottom"], kp["steer_top"], kp.get("crank_axle"))
    part = {k: p for p, ks in DEFAULT_KEYPOINT_PARTS.items() for k in ks}
    out = {}
    for k, x in kp.items():
        local = {"steering": H["steer"], "crank": H["pedal"]}.get(part.get(k))
        y = transform_points(local, x) if local is not None else x.expand(H["global"].shape[0], 3)
        out[k] = transform_points(H["global"], y)
    return out


# ------------------------------------------------------------------ the solver

def _prepare_targets(targets, names, batch_hint):
    if not isinstance(targets, dict):
        raise UserError("ik: targets must be a dict name -> (B, 3) positions")
    missing = [n for n in names if n not in targets]
    if missing:
        raise UserError(f"ik: targets lack {', '.join(missing)} (have {', '.join(sorted(targets)) or 'none'})")
    ts = {n: _finite_tensor(targets[n], f"target {n!r}", (3,)) for n in names}
    B = max([batch_hint] + [_batch_of(t, 1) for t in ts.values()])
    for n, t in ts.items():
        if t.dim() == 2 and t.shape[0] not in (1, B):
            raise UserError(f"ik: target {n!r} has {t.shape[0]} frames, others have {B}")
    return {n: t.reshape(-1, 3).expand(B, 3) for n, t in ts.items()}, B


def solve(rest_joints, targets, init_local_aa=None, init_root=None, objective="pairs", iterations=50,
          lr=0.05, saddle_fit=False, saddle_shared=False, pairs=DEFAULT_PAIRS,
          pelvis_above_seat_m=PELVIS_ABOVE_SEAT_M, up=(0.0, 1.0, 0.0), seat_range_m=SEAT_RANGE_M,
          flag_threshold_m=FLAG_THRESHOLD_M, w_hinge=1.0, w_off_hinge=1e-2, w_prior=1e-4, w_seat=1e-3,
          betas=(0.9, 0.999), pair_weights=None, init="analytic"):
    """Batched keypoint IK for B frames.

    rest_joints (24, 3) metres, canonical frame; targets: name -> (B, 3) or (3,) world positions
    for every target of `pairs` (plus `crank_axle` with saddle_fit); init_local_aa (B, 24, 3) or
    (24, 3) (default: cycling_init_pose); init_root (B, 3) root translation (default: the pelvis on
    its target).  `up` (3,) or (B, 3) is the bike's up direction for the pelvis-above-seat offset.
    saddle_fit slides the seat (and the pelvis target) along crank_axle -> seat within
    seat_range_m; saddle_shared uses one offset for all B frames (one seat post for a sequence).
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
    rest = _finite_tensor(rest_joints, "rest_joints", (24, 3))
    if rest.dim() != 2:
        raise UserError(f"ik: rest_joints must be (24, 3), got {tuple(rest.shape)}")
    hint = 1
    if init_local_aa is not None:
        init_aa = _finite_tensor(init_local_aa, "init_local_aa", (24, 3))
        hint = _batch_of(init_aa, 2)
    if init_root is not None:
        init_root_t = _finite_tensor(init_root, "init_root", (3,))
        hint = max(hint, _batch_of(init_root_t, 1))
    names = [t for _, t in pairs] + (["crank_axle"] if saddle_fit else [])
    tg, B = _prepare_targets(targets, list(dict.fromkeys(names)), hint)
    up_t = _finite_tensor(up, "up", (3,)).reshape(-1, 3).expand(B, 3)
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
    chain = _Chain(rest, init_R, [j for j, _ in pairs])
    axes = hinge_axes(rest).to(f32)
    T0, U = T0.to(f32), U.to(f32)
    P0 = torch.cat([init_aa[:, slot_idx].reshape(B, _N_ROT), root0, s0[:, None]], 1).to(f32)
    prior_w = torch.zeros(P0.shape[1], dtype=f32)
    prior_w[:_N_ROT] = w_prior
    if saddle_fit:
        prior_w[-1] = w_seat
    pw = torch.ones(len(pairs), dtype=f32)
    if pair_weights is not None:
        pw = _finite_tensor(pair_weights, "pair_weights", (len(pairs),)).to(f32)
    chamfer = objective == "chamfer"

    def loss_fn(P):
        rot = rodrigues(P[:, :_N_ROT].view(B, len(SLOT_JOINTS), 3))
        eff = chain(rot, P[:, _N_ROT:_N_ROT + 3])
        tgt = T0 + P[:, -1:, None] * U if saddle_fit else T0
        if chamfer:
            d2 = ((eff[:, :, None] - tgt[:, None]) ** 2).sum(-1)
            fit = 0.5 * (d2.min(2).values.sum(1) + d2.min(1).values.sum(1))
        else:
            fit = (((eff - tgt) ** 2).sum(2) * pw).sum(1)
        h = P[:, 3 * _HINGE_SLOTS.start:3 * _HINGE_SLOTS.stop].view(B, 4, 3)
        theta = (h * axes).sum(-1)
        off = h - theta[..., None] * axes
        hinge = w_hinge * torch.relu(theta - HINGE_MAX_RAD).square().sum(1) + w_off_hinge * off.square().sum((1, 2))
        prior = ((P - P0).square() * prior_w).sum(1)
        return fit + hinge + prior

    hs = slice(3 * _HINGE_SLOTS.start, 3 * _HINGE_SLOTS.stop)

    def project(P):  # in place: hinges never bend backwards; the seat post stays within its travel
        h = P[:, hs].view(B, 4, 3)
        h -= torch.clamp((h * axes).sum(-1), max=0.0)[..., None] * axes
        if saddle_fit:
            P[:, -1].clamp_(lo, hi)

    project(P0)  # a given initial pose may bend a knee backwards
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
    local_aa[:, slot_idx] = P[:, :_N_ROT].view(B, len(SLOT_JOINTS), 3)
    trans = P[:, _N_ROT:_N_ROT + 3].clone()
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

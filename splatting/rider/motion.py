"""Rider motion: SMPL-format pose files (CLIFF, AMASS), the built-in pedalling motion, the paper's
programmatic sweep, and the pedal/steering angles read back from a pose.

Every motion is returned in the canonical frame (X forward, Y up, Z right) as local joint
rotations (N,24,3,3) for the T-posed rider of body.py plus the pelvis's world position (N,3).
SMPL's body frame is Y up, facing +Z, its left at +X; our rest pose is that frame turned by
C = Ry(+90 deg): (X, Y, Z)_canonical = (z, y, -x)_smpl. A local joint rotation converts as
C R C^T; the root as W R C^T, W mapping the file's world frame to ours.
"""
import dataclasses
import math
from pathlib import Path

import numpy as np
import roma
import torch

from cyclist_formats.errors import UserError
from splatting.rider.kinematics import JOINT_INDEX, PARENTS, forward_kinematics
from splatting.rotations import axis_angle_to_rotmat

C_SMPL = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
_RX_PI = np.diag([1.0, -1.0, -1.0])  # OpenCV camera (y down, z ahead) -> Y up
_ZUP_TO_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # Rx(-90 deg)
J = JOINT_INDEX


@dataclasses.dataclass
class Motion:
    local_rotmats: torch.Tensor  # (N, 24, 3, 3) canonical frame
    pelvis: torch.Tensor  # (N, 3) world position of the pelvis joint, canonical frame
    fps: float = 30.0
    source: str = ""
    betas: np.ndarray | None = None
    theta_p: torch.Tensor | None = None  # (N,) radians, where the motion defines them
    theta_s: torch.Tensor | None = None

    def __len__(self):
        return self.local_rotmats.shape[0]

    def root_trans(self, rider):
        """(N,3) root translation that puts `rider`'s pelvis joint on this motion's pelvis."""
        return self.pelvis - rider.joints[0].to(self.pelvis.dtype)


# ----------------------------------------------------------------------------- file loaders

def _load_npz(path):
    path = Path(path)
    if not path.is_file():
        raise UserError(f"motion file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except Exception as e:  # zipfile / pickle / format errors all mean "not a usable npz"
        raise UserError(f"cannot read {path} as .npz: {e}") from None


def _finite(name, a, path):
    if not np.issubdtype(a.dtype, np.number):
        raise UserError(f"{path}: '{name}' is not numeric")
    if not np.isfinite(a).all():
        raise UserError(f"{path}: '{name}' contains NaN or infinite values")


def _arrays(z, path, what, keys):
    """The arrays `keys` of a loaded .npz, each present and finite, or one UserError naming it."""
    for k in keys:
        if k not in z:
            raise UserError(f"{path}: not {what}, missing key '{k}' (has {sorted(z)})")
    for k in keys:
        _finite(k, z[k], path)
    return [z[k] for k in keys]


def _convert(rotmats, root_world, trans_world):
    """SMPL-frame local rotations (N,24,3,3) + file-world translations -> canonical Motion parts."""
    C = torch.from_numpy(C_SMPL)
    W = torch.from_numpy(root_world @ np.eye(3))
    R = torch.as_tensor(rotmats, dtype=torch.float64)
    out = C @ R @ C.T
    out[:, 0] = W @ R[:, 0] @ C.T
    pelvis = torch.as_tensor(trans_world, dtype=torch.float64) @ W.T
    return out, pelvis


def load_cliff(path, world="camera"):
    """CLIFF demo output: `pose` (N,72) axis-angle or (N,24,3,3) rotation matrices, `global_t`
    (N,3) camera-frame translation; `shape` (N,10) kept as betas.

    world="camera" turns the OpenCV camera frame (y down) into a Y-up world facing +X:
    W = C . Rx(pi). The pelvis is placed at the SMPL translation, i.e. it ignores SMPL's
    template pelvis offset (a per-subject constant that the IK root translation absorbs)."""
    z = _load_npz(path)
    pose, t = _arrays(z, path, "a CLIFF result", ("pose", "global_t"))
    n = pose.shape[0] if pose.ndim else 0
    if pose.ndim == 2 and pose.shape[1] == 72:
        R = axis_angle_to_rotmat(torch.from_numpy(pose.reshape(n, 24, 3).astype(np.float64)))
    elif pose.ndim == 4 and pose.shape[1:] == (24, 3, 3):
        R = torch.from_numpy(pose.astype(np.float64))
        if (torch.linalg.det(R) - 1).abs().max() > 1e-3:
            raise UserError(f"{path}: 'pose' rotation matrices are not rotations (det != 1)")
    else:
        raise UserError(f"{path}: 'pose' must be (N,72) axis-angle or (N,24,3,3), got {pose.shape}")
    if t.shape != (n, 3):
        raise UserError(f"{path}: 'global_t' must be ({n},3), got {t.shape}")
    if world == "camera":
        Wm = C_SMPL @ _RX_PI
    elif world == "smpl":
        Wm = C_SMPL
    else:
        raise ValueError(world)
    rot, pelvis = _convert(R, Wm, t)
    betas = z.get("shape")
    return Motion(rot, pelvis, fps=30.0, source=str(path), betas=betas)


def load_amass(path):
    """AMASS: `poses` (N,156) SMPL-H axis-angle (the first 22 joints are SMPL's body; the SMPL
    hand joints stay at rest), `trans` (N,3), Z-up world; `mocap_framerate`, `betas` optional.
    The Z-up world becomes Y up with W = C . Rx(-pi/2)."""
    z = _load_npz(path)
    poses, trans = _arrays(z, path, "an AMASS file", ("poses", "trans"))
    if poses.ndim != 2 or poses.shape[1] != 156:
        raise UserError(f"{path}: 'poses' must be (N,156), got {poses.shape}")
    n = poses.shape[0]
    if trans.shape != (n, 3):
        raise UserError(f"{path}: 'trans' must be ({n},3), got {trans.shape}")
    aa = np.zeros((n, 24, 3))
    aa[:, :22] = poses[:, :66].reshape(n, 22, 3)
    R = axis_angle_to_rotmat(torch.from_numpy(aa))
    rot, pelvis = _convert(R, C_SMPL @ _ZUP_TO_YUP, trans)
    fps = float(z["mocap_framerate"]) if "mocap_framerate" in z else 30.0
    return Motion(rot, pelvis, fps=fps, source=str(path), betas=z.get("betas"))


def load_motion(path):
    """CLIFF or AMASS .npz, told apart by their keys."""
    z = _load_npz(path)
    if "poses" in z:
        return load_amass(path)
    if "pose" in z:
        return load_cliff(path)
    raise UserError(f"{path}: neither a CLIFF ('pose', 'global_t') nor an AMASS ('poses', "
                    f"'trans') file; keys: {sorted(z)}")


# ----------------------------------------------------------------------------- built-in pedalling

@dataclasses.dataclass(frozen=True)
class BikeFit:
    """Where the pedals and the bar sit relative to the rider (pelvis at the origin), scaled by
    the rider's leg and arm lengths so every roster rider reaches them."""
    crank_m: float = 0.17
    seat_tube_deg: float = 73.0  # hip -> bottom bracket direction, from the horizontal
    leg_extension: float = 0.95  # hip-to-ankle distance at the longest point / leg length
    torso_lean_deg: float = 45.0  # trunk from vertical, split over pelvis and spine
    reach: float = 0.78  # shoulder-to-grip distance / arm length
    reach_drop_deg: float = 30.0  # grips below the shoulders' line, degrees
    bar_half_width_m: float = 0.21
    head_tube_deg: float = 72.0  # steering axis from the horizontal (top leans back)

    @property
    def steer_axis(self):
        a = math.radians(self.head_tube_deg)
        return np.array([-math.cos(a), math.sin(a), 0.0])


def _rz(a):
    c, s = torch.cos(a), torch.sin(a)
    o, z = torch.ones_like(a), torch.zeros_like(a)
    return torch.stack([c, -s, z, s, c, z, z, z, o], -1).reshape(a.shape + (3, 3))


def _swing(a, b):
    """Batched smallest rotation turning unit vectors a onto b: (B,3),(B,3) -> (B,3,3)."""
    axis = torch.linalg.cross(a, b)
    s = axis.norm(dim=-1, keepdim=True)
    ang = torch.atan2(s, (a * b).sum(-1, keepdim=True))
    return roma.rotvec_to_rotmat(axis / s.clamp_min(1e-12) * ang)


def pedal_pose(rider_joints, theta_p, theta_s, fit=BikeFit()):
    """Seated pedalling pose at crank angles theta_p and steering theta_s (radians, (B,)).

    Returns (local_rotmats (B,24,3,3), root_trans (B,3), targets) with the pelvis at the origin;
    targets holds the ankle and wrist goals (world) that the pose reaches. Legs and arms are set
    by analytic two-bone IK: knees bend forward, elbows outward and back."""
    theta_p = torch.as_tensor(theta_p, dtype=torch.float64).reshape(-1)
    theta_s = torch.as_tensor(theta_s, dtype=torch.float64).reshape(-1)
    theta_p, theta_s = torch.broadcast_tensors(theta_p, theta_s)
    B = theta_p.shape[0]
    rest = torch.as_tensor(rider_joints, dtype=torch.float64)
    rot = torch.eye(3, dtype=torch.float64).repeat(B, 24, 1, 1)
    root_trans = (-rest[0]).expand(B, 3).clone()

    # Trunk lean forward (a negative turn about +Z tips +Y toward +X); head kept level.
    lean = math.radians(fit.torso_lean_deg)
    for j, share in ((J["pelvis"], 0.4), (J["spine1"], 0.2), (J["spine2"], 0.2), (J["spine3"], 0.2)):
        rot[:, j] = _rz(torch.full((B,), -lean * share, dtype=torch.float64))
    rot[:, J["neck"]] = _rz(torch.full((B,), lean * 0.5, dtype=torch.float64))
    rot[:, J["head"]] = _rz(torch.full((B,), lean * 0.3, dtype=torch.float64))

    joints, _ = forward_kinematics(rest, rot, root_trans)

    # Legs: ankle goals on the crank circle, the foot's ball over the pedal.
    leg = lambda s: (J[f"{s}_hip"], J[f"{s}_knee"], J[f"{s}_ankle"])
    L = _limb_length(rest, "left_hip", "left_knee", "left_ankle")
    hip_mid = 0.5 * (joints[:, J["left_hip"]] + joints[:, J["right_hip"]])
    st = math.radians(fit.seat_tube_deg)
    foot_off = rest[J["left_ankle"]] - rest[J["left_foot"]]
    centre = hip_mid + (fit.leg_extension * L - fit.crank_m) * torch.tensor(
        [math.cos(st), -math.sin(st), 0.0], dtype=torch.float64)
    bb = centre - torch.tensor([foot_off[0], foot_off[1], 0.0], dtype=torch.float64)
    # Right crank forward at theta_p = 0; positive theta_p turns it by -theta_p about +Z.
    crank_r = fit.crank_m * torch.stack([torch.cos(theta_p), -torch.sin(theta_p),
                                         torch.zeros_like(theta_p)], -1)
    targets = {}
    for side, sign in (("right", 1.0), ("left", -1.0)):
        hip = joints[:, J[f"{side}_hip"]]
        goal = centre + sign * crank_r
        goal = torch.cat([goal[:, :2], hip[:, 2:]], 1)  # legs move in their hip's X-Y plane
        targets[f"{side}_ankle"] = goal
        targets[f"{side}_pedal"] = bb + sign * crank_r
        pole = torch.tensor([1.0, 0.3, 0.0], dtype=torch.float64).expand(B, 3)
        _solve_two_bone(rot, rest, root_trans, leg(side), goal, pole)
    # Feet stay level (world orientation of the rest pose): the ankle undoes the leg's turn.
    _, T = forward_kinematics(rest, rot, root_trans)
    for side in ("left", "right"):
        rot[:, J[f"{side}_ankle"]] = T[:, J[f"{side}_knee"], :3, :3].transpose(-1, -2)

    # Arms: grips on a bar that turns by theta_s about the (tilted) steering axis.
    joints, T = forward_kinematics(rest, rot, root_trans)
    arm = lambda s: (J[f"{s}_shoulder"], J[f"{s}_elbow"], J[f"{s}_wrist"])
    A = _limb_length(rest, "left_shoulder", "left_elbow", "left_wrist")
    sh_mid = 0.5 * (joints[:, J["left_shoulder"]] + joints[:, J["right_shoulder"]])
    drop = math.radians(fit.reach_drop_deg)
    bar = sh_mid + fit.reach * A * torch.tensor([math.cos(drop), -math.sin(drop), 0.0],
                                                dtype=torch.float64)
    axis = torch.from_numpy(fit.steer_axis)
    R_s = roma.rotvec_to_rotmat(theta_s[:, None] * axis)  # (B,3,3)
    half = torch.tensor([0.0, 0.0, fit.bar_half_width_m], dtype=torch.float64)
    for side, sign in (("right", 1.0), ("left", -1.0)):
        goal = bar + sign * (R_s @ half)
        targets[f"{side}_wrist"] = goal
        targets[f"{side}_grip"] = goal
        pole = torch.tensor([-0.6, -1.0, 0.5 * sign], dtype=torch.float64).expand(B, 3)
        _solve_two_bone(rot, rest, root_trans, arm(side), goal, pole)
    targets["bottom_bracket"] = bb
    targets["bar_centre"] = bar
    return rot, root_trans, targets


def _limb_length(rest, a, b, c):
    """Rest length of the two-segment limb a -> b -> c (joint names)."""
    return (rest[J[b]] - rest[J[a]]).norm() + (rest[J[c]] - rest[J[b]]).norm()


def _solve_two_bone(rot, rest, root_trans, chain, target, pole):
    """In place: local rotations of joints a and b of chain (a, b, c) so c lands on target."""
    a, b, c = chain
    rot[:, a] = torch.eye(3, dtype=rot.dtype)
    rot[:, b] = torch.eye(3, dtype=rot.dtype)
    joints, T = forward_kinematics(rest, rot, root_trans)
    G = T[..., :3, :3]
    pa, pb, pc = joints[:, a], joints[:, b], joints[:, c]
    l1 = (pb - pa).norm(dim=-1, keepdim=True)
    l2 = (pc - pb).norm(dim=-1, keepdim=True)
    d_vec = target - pa
    d = d_vec.norm(dim=-1, keepdim=True)
    u = d_vec / d
    d = d.clamp((l1 - l2).abs() + 1e-6, l1 + l2 - 1e-6)  # unreachable: straighten toward it
    n = pole - (pole * u).sum(-1, keepdim=True) * u
    n = n / n.norm(dim=-1, keepdim=True)
    cos_a = ((l1 ** 2 + d ** 2 - l2 ** 2) / (2 * l1 * d)).clamp(-1, 1)
    b_goal = pa + l1 * (cos_a * u + torch.sqrt(1 - cos_a ** 2) * n)
    c_goal = pa + d * u
    Gp = G[:, PARENTS[a]]
    Q1 = _swing((pb - pa) / l1, (b_goal - pa) / l1)
    rot[:, a] = Gp.transpose(-1, -2) @ Q1 @ Gp  # G_a = Q1 Gp = Gp R_a
    Ga = Q1 @ Gp
    e2 = Q1 @ ((pc - pb) / l2).unsqueeze(-1)
    Q2 = _swing(e2.squeeze(-1), (c_goal - b_goal) / l2)
    rot[:, b] = Ga.transpose(-1, -2) @ Q2 @ Ga


def pedalling_motion(rider, n_frames=36, cadence_rpm=80.0, theta_s_deg=0.0, fit=BikeFit()):
    """The default motion: one crank revolution in n_frames, steering fixed."""
    if n_frames < 1:
        raise UserError("n_frames must be >= 1")
    tp = torch.arange(n_frames, dtype=torch.float64) * (2 * math.pi / n_frames)
    ts = torch.full_like(tp, math.radians(theta_s_deg))
    rot, root, _ = pedal_pose(rider.joints, tp, ts, fit)
    fps = n_frames * cadence_rpm / 60.0
    return Motion(rot, root + rider.joints[0].double(), fps=fps, source="builtin:pedalling",
                  theta_p=tp, theta_s=ts)


def sweep_motion(rider, theta_p_deg=(0.0, 360.0, 30.0), theta_s_deg=(-30.0, 30.0, 10.0),
                 fit=BikeFit()):
    """The paper's programmatic mode: every (theta_p, theta_s) on a grid, each range given as
    (start, stop, step) in degrees, stop excluded for theta_p (a full turn) and included for
    theta_s."""
    def grid(r, include_stop):
        a, b, s = (float(x) for x in r)
        if s <= 0 or b < a:
            raise UserError(f"bad sweep range {r}: need start <= stop and step > 0")
        n = int(math.floor((b - a) / s + 1e-9)) + (1 if include_stop else 0)
        return torch.tensor([a + i * s for i in range(max(n, 1))], dtype=torch.float64)
    gp, gs = grid(theta_p_deg, False), grid(theta_s_deg, True)
    tp, ts = torch.meshgrid(torch.deg2rad(gp), torch.deg2rad(gs), indexing="ij")
    tp, ts = tp.reshape(-1), ts.reshape(-1)
    rot, root, _ = pedal_pose(rider.joints, tp, ts, fit)
    return Motion(rot, root + rider.joints[0].double(), source="builtin:sweep",
                  theta_p=tp, theta_s=ts)


# ----------------------------------------------------------------------------- angles from a pose

def theta_from_pose(joints, steer_axis=None):
    """(theta_p, theta_s) in radians from posed joints (..., 24, 3) in the canonical bike frame.

    theta_p: the ankle-to-ankle vector projected on the X-Y plane (the crank plane), right minus
    left; the right crank points forward at 0 and positive theta_p is forward pedalling.
    theta_s: the wrist-to-wrist vector projected on the X-Z plane (the paper); given the
    steering axis (unit, in the X-Y plane), on the plane normal to it instead, which removes the
    cos(head-tube tilt) shrink of the paper's projection."""
    joints = torch.as_tensor(joints)
    if joints.shape[-2:] != (24, 3):
        raise UserError(f"joints must be (...,24,3), got {tuple(joints.shape)}")
    if not torch.isfinite(joints).all():
        raise UserError("joints contain NaN or infinite values")
    da = joints[..., J["right_ankle"], :] - joints[..., J["left_ankle"], :]
    theta_p = torch.atan2(-da[..., 1], da[..., 0])
    dw = joints[..., J["right_wrist"], :] - joints[..., J["left_wrist"], :]
    if steer_axis is None:
        ex = torch.tensor([1.0, 0.0, 0.0], dtype=joints.dtype)
    else:
        v = torch.as_tensor(steer_axis, dtype=joints.dtype)
        ex = torch.linalg.cross(v / v.norm(), torch.tensor([0.0, 0.0, 1.0], dtype=joints.dtype))
    theta_s = torch.atan2((dw * ex).sum(-1), dw[..., 2])
    return theta_p, theta_s

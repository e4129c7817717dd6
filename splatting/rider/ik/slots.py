"""The IK's parameter layout and the rider's hinge joints: which joints are free, in which slot
order, which bend like hinges and about which axis, and the default keypoint pairs."""
import math

import torch

from cyclist_formats.errors import UserError
from splatting.rider.kinematics import JOINT_INDEX, PARENTS

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
EXACT_START_M = 1e-3  # a start this close to every target is returned without Adam (solver.solve)
# continuation past `iterations` (solver.solve): frames whose worst pair is still farther than
# CONVERGED_M go on, CHECK_EVERY iterations at a time, while their kept loss still drops by
# MIN_GAIN per check, up to EXTEND_FACTOR x iterations (300 for the default 50).  Measured
# (docs/ik.md): riders at the saddle's lowest are 1.2-2.4 cm off after 50 steps, 0.8-1.3 cm after
# 100 and 0.3-0.4 cm after 300, their loss dropping 10-60 % per 25 steps; targets out of reach
# gain 0-7 % per 25 steps (5 % for 250 steps would shrink a residual by a quarter only).
CONVERGED_M = 0.01
CHECK_EVERY = 25
MIN_GAIN = 0.05
EXTEND_FACTOR = 6
OBJECTIVES = ("pairs", "chamfer")

# parameter slots: root orientation, then the 11 joints with the four hinges last (one slice)
SLOT_JOINTS = ("pelvis", "spine1", "left_shoulder", "right_shoulder", "left_hip", "right_hip",
                "left_ankle", "right_ankle", "left_elbow", "right_elbow", "left_knee", "right_knee")
HINGE_SLOTS = slice(8, 12)
N_ROT = len(SLOT_JOINTS) * 3  # 36 rotation columns, then 3 translation, then 1 seat offset


def pair_name(joint, target):
    return f"{joint}->{target}"


def skeleton_key(rest):
    """A hashable key of a rest skeleton's exact values: functions of the rest skeleton alone are
    computed once per rider (a dataset poses the same few riders thousands of times)."""
    return torch.as_tensor(rest, dtype=torch.float64).detach().contiguous().numpy().tobytes()


_AXES = {}


def hinge_axes(rest_joints):
    """Unit flexion axes (4, 3) of the hinge slots (knees, elbows) in the rest frame: positive
    rotation about it swings the child segment toward HINGE_FLEX_DIRECTION."""
    key = skeleton_key(rest_joints)
    if key not in _AXES:
        _AXES[key] = _hinge_axes(torch.as_tensor(rest_joints, dtype=torch.float64))
    return _AXES[key].clone()


def _hinge_axes(rest):
    axes = []
    for name in SLOT_JOINTS[HINGE_SLOTS]:
        j = JOINT_INDEX[name]
        u = rest[j] - rest[PARENTS[j]]  # the parent segment (thigh, upper arm) in the rest pose
        a = torch.linalg.cross(u, torch.tensor(HINGE_FLEX_DIRECTION[name], dtype=torch.float64))
        n = torch.linalg.vector_norm(a)
        if not n > 1e-6:
            raise UserError(f"rest skeleton: {name}'s parent segment is parallel to its flexion direction")
        axes.append(a / n)
    return torch.stack(axes)

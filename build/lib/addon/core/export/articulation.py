"""The bike's joints as docs/contract.md defines them, from keypoints.json (numpy only).

- `steering`: revolute about v = unit(steer_top - steer_bottom) through steer_bottom; joint
  value +theta_s turns the front wheel to the rider's left (docs/contract.md H_s).
- `crank`: continuous about the axle through crank_axle parallel to canonical Z; joint value
  +theta_p is forward pedalling, a rotation by -theta_p about +Z, i.e. by +theta_p about -Z.
Everything here is in the canonical frame (X forward, Y up, Z right), metres and radians.
"""
from dataclasses import dataclass

import numpy as np

from ..contract import UserError, bike_folder

PARTS = ("frame", "steering", "crank")
CRANK_AXIS = np.array([0.0, 0.0, -1.0])  # +theta_p about this = -theta_p about +Z


@dataclass
class Joint:
    name: str  # the child part's name
    kind: str  # "revolute" or "continuous"
    parent: str
    pivot: np.ndarray  # (3,) canonical, a point on the axis (the child's frame origin)
    axis: np.ndarray  # (3,) unit, canonical; positive joint values rotate right-handed about it


@dataclass
class Rig:
    parts: list  # part names present, root first
    joints: list  # [Joint]
    keypoints: dict  # name -> (3,) canonical rest position
    keypoint_part: dict  # name -> part that carries it

    def joint(self, name):
        return next((j for j in self.joints if j.name == name), None)

    def origin(self, part):
        """The part's frame origin (its pivot) in the canonical frame; frame's is the origin."""
        j = self.joint(part)
        return np.zeros(3) if j is None else j.pivot


def rotation(axis, angle):
    """Right-handed rotation matrix by `angle` radians about unit `axis` (Rodrigues)."""
    a = np.asarray(axis, float)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


def quaternion_xyzw(axis, angle):
    """The same rotation as a unit quaternion (x, y, z, w), glTF's order."""
    a = np.asarray(axis, float)
    return np.concatenate([np.sin(angle / 2) * a, [np.cos(angle / 2)]])


def rig_from_keypoints(doc, has_crank=True, source="keypoints.json"):
    """keypoints.json object -> Rig.  UserError for missing keypoints or a degenerate axis."""
    kps, part_of = bike_folder.parse_keypoints_doc(doc, has_crank, source=source)
    need = ["steer_top", "steer_bottom"] + (["crank_axle"] if has_crank else [])
    missing = [k for k in need if k not in kps]
    if missing:
        raise UserError(f"{source} lacks keypoints {', '.join(missing)}")
    d = kps["steer_top"] - kps["steer_bottom"]
    if not np.linalg.norm(d) > 1e-6:
        raise UserError(f"{source}: steer_top and steer_bottom coincide: no steering axis")
    joints = [Joint("steering", "revolute", "frame", kps["steer_bottom"].copy(), d / np.linalg.norm(d))]
    parts = ["frame", "steering"]
    if has_crank:
        joints.append(Joint("crank", "continuous", "frame", kps["crank_axle"].copy(), CRANK_AXIS.copy()))
        parts.append("crank")
    return Rig(parts, joints, kps, part_of)


def part_matrices(rig, theta_s, theta_p):
    """Canonical world-from-part-rest 4x4 matrices at (theta_s, theta_p) radians (frame fixed)."""
    out = {"frame": np.eye(4)}
    for j in rig.joints:
        ang = theta_s if j.name == "steering" else theta_p
        M = np.eye(4)
        M[:3, :3] = rotation(j.axis, ang)
        M[:3, 3] = j.pivot - M[:3, :3] @ j.pivot
        out[j.name] = M
    return out

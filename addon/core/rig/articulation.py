"""Apply docs/contract.md's 8-DoF bicycle pose to a bike armature, and read the posed keypoints.

H_s: +theta_s about the steering bone's local Y (= steer_bottom -> steer_top, right-hand rule).
H_p: -theta_p about the crank bone's local Y (= canonical +Z), so +theta_p pedals forward.
H_g = T(t) Rz Ry Rx in the canonical frame, set as the armature object's world matrix.
Wheel sub-parts: -wheel angle about their bones' local Y (= canonical +Z), the wheel angle being
theta_p times the armature's "gear_ratio" unless given (a coasting wheel turns with the crank
still); the pedal bodies need nothing (their bones do not inherit the crank's rotation).
"""
import math

import bpy
import numpy as np
from mathutils import Matrix

from ..frames import matrix_to_blender, to_canonical
from ..procedural.layout import KEYPOINT_NAMES


def global_matrix(rot_xyz_deg=(0, 0, 0), t=(0, 0, 0)):
    """Canonical 4x4 H_g = T(t) . Rz . Ry . Rx (angles in degrees)."""
    ax, ay, az = (math.radians(float(a)) for a in rot_xyz_deg)
    cx, sx, cy, sy, cz, sz = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay), math.cos(az), math.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    m = np.eye(4)
    m[:3, :3] = rz @ ry @ rx
    m[:3, 3] = np.asarray(t, float)
    return m


def wheel_angle_deg(arm_obj, theta_p_deg, wheel_deg=None):
    """The wheels' rolling angle (degrees, + = rolling forward): wheel_deg when given, else
    theta_p x the armature's gear ratio (0 without one)."""
    if wheel_deg is not None:
        return float(wheel_deg)
    return float(theta_p_deg) * float(arm_obj.get("gear_ratio", 0.0))


def apply_pose(arm_obj, theta_p_deg, theta_s_deg, rot_xyz_deg=(0, 0, 0), t=(0, 0, 0), wheel_deg=None):
    """Pose the armature (and the parts bone-parented to it); updates the view layer.
    wheel_deg: the wheel sub-parts' rolling angle (default: theta_p x gear ratio)."""
    vals = [theta_p_deg, theta_s_deg, *rot_xyz_deg, *t] + ([wheel_deg] if wheel_deg is not None else [])
    if not all(math.isfinite(float(v)) for v in vals):
        raise ValueError(f"pose has a non-finite value: {vals}")
    pbs = arm_obj.pose.bones
    st = pbs["steering"]
    st.rotation_mode = "XYZ"
    st.rotation_euler = (0.0, math.radians(float(theta_s_deg)), 0.0)
    if "crank" in pbs:
        cr = pbs["crank"]
        cr.rotation_mode = "XYZ"
        cr.rotation_euler = (0.0, -math.radians(float(theta_p_deg)), 0.0)
    w = wheel_angle_deg(arm_obj, theta_p_deg, wheel_deg)
    for name in ("front_wheel", "rear_wheel"):
        if name in pbs:
            pbs[name].rotation_mode = "XYZ"
            pbs[name].rotation_euler = (0.0, -math.radians(w), 0.0)
    arm_obj.matrix_world = Matrix(matrix_to_blender(global_matrix(rot_xyz_deg, t)).tolist())
    bpy.context.view_layer.update()


def posed_keypoints(arm_obj):
    """{keypoint name: canonical [x, y, z]} from the evaluated (posed) keypoint bones."""
    dg = bpy.context.evaluated_depsgraph_get()
    ev = arm_obj.evaluated_get(dg)
    mw = ev.matrix_world
    out = {}
    for name in KEYPOINT_NAMES:
        pb = ev.pose.bones.get(name)
        if pb is not None:
            out[name] = [float(c) for c in to_canonical(np.array(mw @ pb.head))]
    return out

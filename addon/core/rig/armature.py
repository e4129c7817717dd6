"""The bike armature: part bones (frame, steering, crank) and one short bone per keypoint.

Bones (Blender frame, armature object at identity):
- `frame`: root, at the ground origin pointing up.
- `steering`: head = steer_bottom, tail = steer_top, so its local Y is the steering axis v and a
  pose rotation by +theta about local Y is docs/contract.md's H_s(theta).
- `crank`: head = crank_axle, tail = crank_axle + 0.1 m along canonical +Z, so a rotation by
  -theta_p about local Y is H_p(theta_p).
- keypoint bones: head at the keypoint, 3 cm long (canonical +Y), parented (unconnected) to the
  part bone that carries the keypoint (layout.bone_parent).
- sub-parts (docs/contract.md "Sub-parts"), only when their mesh exists: `front_wheel` (parent
  steering) and `rear_wheel` (parent frame), head at the axle, tail 0.1 m along canonical +Z
  like the crank's, so a rotation by -angle about local Y rolls the wheel forward by angle; the
  pedal bodies hang on the keypoint bones `pedal_left` / `pedal_right`, which then do not inherit
  the crank's rotation (their head follows the crank, their orientation stays the frame's): the
  pedals stay level.  The armature object's custom property "gear_ratio" (wheel turns per crank
  turn) couples the wheels to theta_p (articulation.apply_pose).
Part meshes are bone-parented (rigid), which behaves the same in Blender 3.4 and 5.0.
"""
import bpy
import numpy as np
from mathutils import Matrix, Vector

from ..frames import to_blender
from ..procedural.layout import KEYPOINT_NAMES, bone_parent

KP_BONE_LEN = 0.03


WHEEL_BONES = {"front_wheel": ("front_axle", "steering"), "rear_wheel": ("rear_axle", "frame")}
PEDAL_BONES = ("pedal_left", "pedal_right")


def build_armature(keypoints, spec, parts, gear_ratio=None):
    """Create the object `armature` (identity transform) in the scene; returns it.  parts: the
    part (and sub-part) object names; gear_ratio: stored on the armature when it has wheels."""
    data = bpy.data.armatures.new("armature")
    arm = bpy.data.objects.new("armature", data)
    bpy.context.scene.collection.objects.link(arm)
    arm.show_in_front = True
    vl = bpy.context.view_layer
    for o in vl.objects:
        o.select_set(False)
    vl.objects.active = arm
    arm.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    eb = data.edit_bones
    B = lambda p: Vector(to_blender(p).tolist())  # noqa: E731

    def bone(name, head, tail, parent=None):
        b = eb.new(name)
        b.head, b.tail = B(head), B(tail)
        b.roll = 0.0
        if parent:
            b.parent = eb[parent]
            b.use_connect = False
        return b

    bone("frame", [0, 0, 0], [0, 0.2, 0])
    bone("steering", keypoints["steer_bottom"], keypoints["steer_top"], "frame")
    if "crank" in parts:
        ca = np.asarray(keypoints["crank_axle"])
        bone("crank", ca, ca + [0, 0, 0.1], "frame")
    for name in KEYPOINT_NAMES:
        p = np.asarray(keypoints[name])
        parent = bone_parent(name, spec)
        if parent not in ("frame", "steering", "crank") or (parent == "crank" and "crank" not in parts):
            parent = "frame"
        b = bone(name, p, p + [0, KP_BONE_LEN, 0], parent)
        if name in PEDAL_BONES and name in parts and parent == "crank":
            b.use_inherit_rotation = False  # the pedal body keeps the frame's orientation: level
    for name, (axle, parent) in WHEEL_BONES.items():
        if name in parts:
            a = np.asarray(keypoints[axle])
            bone(name, a, a + [0, 0, 0.1], parent)
    bpy.ops.object.mode_set(mode="OBJECT")
    arm.select_set(False)
    if gear_ratio is not None:
        arm["gear_ratio"] = float(gear_ratio)
    return arm


def attach(obj, arm, bone_name):
    """Rigidly parent obj to a bone, keeping its current world placement (rest pose)."""
    bone = arm.data.bones[bone_name]
    obj.parent = arm
    obj.parent_type = "BONE"
    obj.parent_bone = bone_name
    # Blender's bone-parent matrix sits at the bone's tail: undo it at rest.
    rest = arm.matrix_world @ bone.matrix_local @ Matrix.Translation((0.0, bone.length, 0.0))
    obj.matrix_parent_inverse = rest.inverted()

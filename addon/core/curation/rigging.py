"""Rig the curated parts: the armature from the keypoints, the parts parented to its bones."""
import bpy

from ..contract import UserError
from ..procedural.layout import KEYPOINT_NAMES
from ..rig import armature as arm_mod
from .keypoint_empties import current_keypoints
from .scene_state import KP_COLLECTION, PARTS, SOURCE


def spec_like(parts):
    return {"rideable": "bicycle" if "crank" in parts else "no_crank"}


def build_rig():
    kp = current_keypoints()
    missing = [k for k in KEYPOINT_NAMES if k not in kp]
    if missing:
        raise UserError(f"keypoint '{missing[0]}' is missing: place it before building the rig")
    parts = {n: bpy.data.objects[n] for n in PARTS if n in bpy.data.objects}
    if "frame" not in parts or "steering" not in parts:
        raise UserError("split the parts before building the rig")
    old = bpy.data.objects.get("armature")
    if old is not None:
        for o in parts.values():
            mw = o.matrix_world.copy()
            o.parent = None
            o.matrix_world = mw
        bpy.data.objects.remove(old, do_unlink=True)
        for a in list(bpy.data.armatures):
            if a.users == 0:
                bpy.data.armatures.remove(a)
    arm = arm_mod.build_armature({k: list(map(float, v)) for k, v in kp.items()}, spec_like(parts), list(parts))
    for name, o in parts.items():
        arm_mod.attach(o, arm, name)
    bpy.context.view_layer.update()
    return arm, kp, parts


def remove_helpers():
    src = bpy.data.objects.get(SOURCE)
    if src is not None:
        me = src.data
        bpy.data.objects.remove(src, do_unlink=True)
        if me.users == 0:
            bpy.data.meshes.remove(me)
    coll = bpy.data.collections.get(KP_COLLECTION)
    if coll is not None:
        for o in list(coll.objects):
            bpy.data.objects.remove(o, do_unlink=True)
        bpy.data.collections.remove(coll)

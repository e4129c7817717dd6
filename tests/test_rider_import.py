"""`rider import`: a user's rigged human -> roster rider (issue 16).

The rigged humans are made here: a roster (anny) rider's T-posed mesh with an armature of 24 bones at its
joints under Mixamo (`mixamorig:`) or Rigify (`DEF-`) names, plus unmapped bones that carry part of the
weights (a thumb, a neck segment), its weights as vertex groups and an image texture on a UV map; exported
to .glb and .fbx with Blender's own exporters.  Ground truth for the skinning is Blender itself: the
re-imported file's armature posed with the same joint rotations (addon.core.rider_rig.pose_rig) and its
evaluated mesh compared vertex by vertex with the imported rider's LBS."""
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from cyclist_formats import rider_file
from cyclist_formats.errors import UserError
from splatting.rider.kinematics import JOINT_NAMES, PARENTS

bpy = pytest.importorskip("bpy")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SOURCE_RIDER = "f_teen_slim_150"

# The names a Mixamo / Rigify rig uses, written out here (not taken from the table under test).
MIXAMO = {
    "pelvis": "Hips", "left_hip": "LeftUpLeg", "right_hip": "RightUpLeg", "spine1": "Spine",
    "left_knee": "LeftLeg", "right_knee": "RightLeg", "spine2": "Spine1", "left_ankle": "LeftFoot",
    "right_ankle": "RightFoot", "spine3": "Spine2", "left_foot": "LeftToeBase", "right_foot": "RightToeBase",
    "neck": "Neck", "left_collar": "LeftShoulder", "right_collar": "RightShoulder", "head": "Head",
    "left_shoulder": "LeftArm", "right_shoulder": "RightArm", "left_elbow": "LeftForeArm",
    "right_elbow": "RightForeArm", "left_wrist": "LeftHand", "right_wrist": "RightHand",
    "left_hand": "LeftHandMiddle1", "right_hand": "RightHandMiddle1"}
MIXAMO = {j: "mixamorig:" + n for j, n in MIXAMO.items()}
RIGIFY = {
    "pelvis": "DEF-spine", "left_hip": "DEF-thigh.L", "right_hip": "DEF-thigh.R", "spine1": "DEF-spine.001",
    "left_knee": "DEF-shin.L", "right_knee": "DEF-shin.R", "spine2": "DEF-spine.002", "left_ankle": "DEF-foot.L",
    "right_ankle": "DEF-foot.R", "spine3": "DEF-spine.003", "left_foot": "DEF-toe.L", "right_foot": "DEF-toe.R",
    "neck": "DEF-spine.004", "left_collar": "DEF-shoulder.L", "right_collar": "DEF-shoulder.R",
    "head": "DEF-spine.006", "left_shoulder": "DEF-upper_arm.L", "right_shoulder": "DEF-upper_arm.R",
    "left_elbow": "DEF-forearm.L", "right_elbow": "DEF-forearm.R", "left_wrist": "DEF-hand.L",
    "right_wrist": "DEF-hand.R", "left_hand": "DEF-f_middle.01.L", "right_hand": "DEF-f_middle.01.R"}
# unmapped bones: (name, parent joint, joint whose weights it takes half of, or None)
EXTRA = {"mixamo": [("mixamorig:LeftHandThumb1", "left_wrist", "left_wrist"),
                    ("mixamorig:RightHandThumb1", "right_wrist", "right_wrist"),
                    ("mixamorig:HeadTop_End", "head", None)],
         "rigify": [("DEF-thigh.L.001", "left_hip", "left_hip"), ("DEF-thigh.R.001", "right_hip", "right_hip")]}
TEX = 32  # texture: pixel (x, y) = (x / 31, y / 31, 0.25), a ramp bilinear sampling reproduces exactly


@pytest.fixture(scope="module")
def source():
    torch.set_num_threads(1)
    from splatting.rider.roster import load_rider
    return load_rider(SOURCE_RIDER)


def expected_uv(vertices):
    """The UV the factory gives each vertex: a planar map of (Z, Y) into [0.1, 0.9]^2."""
    v = np.asarray(vertices, np.float64)
    lo, hi = v.min(0), v.max(0)
    return np.stack([0.1 + 0.8 * (v[:, 2] - lo[2]) / (hi[2] - lo[2]),
                     0.1 + 0.8 * (v[:, 1] - lo[1]) / (hi[1] - lo[1])], 1)


def expected_colors(vertices):
    uv = expected_uv(vertices)
    rgb = np.empty((len(uv), 3))
    rgb[:, :2] = (uv * TEX - 0.5) / (TEX - 1)
    rgb[:, 2] = 0.25
    return rgb


def write_texture(path):
    img = bpy.data.images.new("skin_ramp", TEX, TEX)
    x, y = np.meshgrid(np.arange(TEX) / (TEX - 1), np.arange(TEX) / (TEX - 1))
    px = np.stack([x, y, np.full_like(x, 0.25), np.ones_like(x)], -1).astype(np.float32)
    img.pixels.foreach_set(px.ravel())
    img.filepath_raw = str(path)
    img.file_format = "PNG"
    img.save()
    return img


def build_rigged_human(rider, scheme, texture=None, a_pose_deg=0.0):
    """The rider as a skinned mesh + armature in the current (empty) scene; returns (armature, mesh)."""
    from mathutils import Matrix, Vector

    from addon.core.frames import to_blender
    names = {"mixamo": MIXAMO, "rigify": RIGIFY}[scheme]
    Vc = rider.vertices.double().numpy()
    V, J = to_blender(Vc), to_blender(rider.joints.double().numpy())
    F = rider.faces.numpy()
    scene = bpy.context.scene
    me = bpy.data.meshes.new("body")
    me.from_pydata(V.tolist(), [], F.tolist())
    me.polygons.foreach_set("use_smooth", np.ones(len(me.polygons), dtype=bool))  # as people are modelled
    me.update()
    body = bpy.data.objects.new("body", me)
    scene.collection.objects.link(body)
    arm = bpy.data.objects.new("rig", bpy.data.armatures.new("rig"))
    scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    eb = arm.data.edit_bones
    first_child = {0: 3, 9: 12}  # pelvis -> spine1, spine3 -> neck (the others have one child or none)
    for j, name in enumerate(JOINT_NAMES):
        kids = [c for c, p in enumerate(PARENTS) if p == j]
        if kids:
            tail = J[first_child.get(j, kids[0])]
        else:  # a leaf: along its parent segment
            d = J[j] - J[PARENTS[j]]
            tail = J[j] + 0.05 * d / np.linalg.norm(d)
        b = eb.new(names[name])
        b.head, b.tail = Vector(J[j].tolist()), Vector(tail.tolist())
        if PARENTS[j] >= 0:
            b.parent = eb[names[JOINT_NAMES[PARENTS[j]]]]
    for name, parent, _ in EXTRA[scheme]:
        p = eb[names[parent]]
        b = eb.new(name)
        b.head, b.tail = p.head.copy(), p.head + (p.tail - p.head) * 0.5
        b.parent = p
    bpy.ops.object.mode_set(mode="OBJECT")
    W = rider.weights.double().numpy().copy()
    groups = {}
    for j, name in enumerate(JOINT_NAMES):
        groups[names[name]] = W[:, j].copy()
    for name, _, share in EXTRA[scheme]:
        if share:  # half of the joint's weight moves to the unmapped child bone
            groups[name] = groups[names[share]] * 0.5
            groups[names[share]] *= 0.5
    for gname, w in groups.items():
        vg = body.vertex_groups.new(name=gname)
        for i in np.flatnonzero(w > 1e-6):
            vg.add([int(i)], float(w[i]), "REPLACE")
    mod = body.modifiers.new("Armature", "ARMATURE")
    mod.object = arm
    body.parent = arm
    if texture is not None:
        uv = expected_uv(Vc)
        layer = me.uv_layers.new(name="UVMap")
        loop_v = np.empty(len(me.loops), np.int64)
        me.loops.foreach_get("vertex_index", loop_v)
        layer.data.foreach_set("uv", uv[loop_v].astype(np.float32).ravel())
        mat = bpy.data.materials.new("skin")
        if bpy.app.version < (5, 0, 0):
            mat.use_nodes = True
        nt = mat.node_tree
        bsdf = next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED")
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = texture
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
        me.materials.append(mat)
    if a_pose_deg:  # arms down by a_pose_deg, then made the rest pose (mesh and armature)
        for side, sign in (("left", 1.0), ("right", -1.0)):
            pb = arm.pose.bones[names[f"{side}_shoulder"]]
            head = Vector(J[JOINT_NAMES.index(f"{side}_shoulder")].tolist())
            # the left arm points along Blender +Y (canonical -Z): a negative turn about the forward
            # axis (Blender X) swings it down; the right arm (-Y) the other way
            R = Matrix.Rotation(math.radians(sign * -a_pose_deg), 4, "X")
            pb.matrix = Matrix.Translation(head) @ R @ Matrix.Translation(-head) @ pb.matrix
            bpy.context.view_layer.update()
        dg = bpy.context.evaluated_depsgraph_get()
        ev = body.evaluated_get(dg).to_mesh()
        co = np.empty(len(ev.vertices) * 3)
        ev.vertices.foreach_get("co", co)
        body.evaluated_get(dg).to_mesh_clear()
        me.vertices.foreach_set("co", co)
        me.update()
        bpy.context.view_layer.objects.active = arm
        bpy.ops.object.mode_set(mode="POSE")
        bpy.ops.pose.armature_apply(selected=False)
        bpy.ops.object.mode_set(mode="OBJECT")
    return arm, body


def export(path):
    if str(path).endswith(".glb"):
        bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB")
    else:
        bpy.ops.export_scene.fbx(filepath=str(path), add_leaf_bones=False, path_mode="COPY", embed_textures=True)
    assert os.path.isfile(path)

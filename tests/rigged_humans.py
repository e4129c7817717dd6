"""Rigged humans for the `rider import` tests, made in Blender from a roster rider: its T-posed mesh with
an armature of 24 bones at its joints under the names of a naming family (Mixamo, Rigify, Unreal, Biped,
VRoid, ...), helper bones that must never become joints, its weights as vertex groups and an image
texture on a planar UV map; exported with Blender's own glTF / FBX exporters.  Also the refused files
(an unrigged mesh, a 3-bone chain, a glb requiring an extension) and the Blender half of the import run
in this process.  Needs the bpy module (the importing test skips without it)."""
import json
import math
import os
import struct
import subprocess
import sys

import bpy
import numpy as np
import torch

from splatting.rider.kinematics import JOINT_NAMES, PARENTS

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


def family(center, limbs, left, right):
    """{joint: bone name}: centre joints as given, limb joints from templates filled with each side's word."""
    out = dict(center)
    for side, word in (("left", left), ("right", right)):
        out.update({f"{side}_{j}": n.format(s=word) for j, n in limbs.items()})
    return out


LIMB_JOINTS = ("hip", "knee", "ankle", "foot", "collar", "shoulder", "elbow", "wrist", "hand")
# Naming families of published rigs, written out here (not taken from the code under test).
FAMILIES = {
    "mixamo": MIXAMO,
    "mixamo_bare": {j: n.split(":")[1] for j, n in MIXAMO.items()},
    "mixamo1": {j: n.replace("mixamorig:", "mixamorig1:") for j, n in MIXAMO.items()},
    "rigify": RIGIFY,
    "unreal": family({"pelvis": "pelvis", "spine1": "spine_01", "spine2": "spine_02", "spine3": "spine_03",
                      "neck": "neck_01", "head": "head"},
                     dict(zip(LIMB_JOINTS, ("thigh_{s}", "calf_{s}", "foot_{s}", "ball_{s}", "clavicle_{s}",
                                            "upperarm_{s}", "lowerarm_{s}", "hand_{s}", "middle_01_{s}"))), "l", "r"),
    "biped": family({"pelvis": "Bip01 Pelvis", "spine1": "Bip01 Spine", "spine2": "Bip01 Spine1",
                     "spine3": "Bip01 Spine2", "neck": "Bip01 Neck", "head": "Bip01 Head"},
                    dict(zip(LIMB_JOINTS, ("Bip01 {s} Thigh", "Bip01 {s} Calf", "Bip01 {s} Foot", "Bip01 {s} Toe0",
                                           "Bip01 {s} Clavicle", "Bip01 {s} UpperArm", "Bip01 {s} Forearm",
                                           "Bip01 {s} Hand", "Bip01 {s} Finger2"))), "L", "R"),
    "vroid": family({"pelvis": "J_Bip_C_Hips", "spine1": "J_Bip_C_Spine", "spine2": "J_Bip_C_Chest",
                     "spine3": "J_Bip_C_UpperChest", "neck": "J_Bip_C_Neck", "head": "J_Bip_C_Head"},
                    dict(zip(LIMB_JOINTS, ("J_Bip_{s}_UpperLeg", "J_Bip_{s}_LowerLeg", "J_Bip_{s}_Foot",
                                           "J_Bip_{s}_ToeBase", "J_Bip_{s}_Shoulder", "J_Bip_{s}_UpperArm",
                                           "J_Bip_{s}_LowerArm", "J_Bip_{s}_Hand", "J_Bip_{s}_Middle1"))), "L", "R"),
    "character_creator": family(
        {"pelvis": "CC_Base_Hip", "spine1": "CC_Base_Waist", "spine2": "CC_Base_Spine01", "spine3": "CC_Base_Spine02",
         "neck": "CC_Base_NeckTwist01", "head": "CC_Base_Head"},
        dict(zip(LIMB_JOINTS, ("CC_Base_{s}_Thigh", "CC_Base_{s}_Calf", "CC_Base_{s}_Foot", "CC_Base_{s}_ToeBase",
                               "CC_Base_{s}_Clavicle", "CC_Base_{s}_Upperarm", "CC_Base_{s}_Forearm",
                               "CC_Base_{s}_Hand", "CC_Base_{s}_Mid1"))), "L", "R"),
    # Sketchfab's export: spaces kept, every name numbered
    "sketchfab": {j: f"{n}_{i:02d}" for i, (j, n) in enumerate(family(
        {"pelvis": "Hips", "spine1": "Spine", "spine2": "Spine1", "spine3": "Chest", "neck": "Neck", "head": "Head"},
        dict(zip(LIMB_JOINTS, ("{s} leg", "{s} shin", "{s} foot", "{s} toe", "{s} shoulder", "{s} arm",
                               "{s} forearm", "{s} hand", "{s} middle finger1"))), "Left", "Right").items())},
    "blender_lr": family({"pelvis": "hips", "spine1": "spine", "spine2": "spine.001", "spine3": "chest",
                          "neck": "neck", "head": "head"},
                         dict(zip(LIMB_JOINTS, ("thigh.{s}", "shin.{s}", "foot.{s}", "toe.{s}", "shoulder.{s}",
                                                "upper_arm.{s}", "forearm.{s}", "hand.{s}", "f_middle.01.{s}"))), "L", "R"),
    "kaykit": family({"pelvis": "hips", "spine1": "spine", "spine2": "-", "spine3": "chest", "neck": "-",
                      "head": "head"},
                     dict(zip(LIMB_JOINTS, ("upperleg.{s}", "lowerleg.{s}", "foot.{s}", "toes.{s}", "-",
                                            "upperarm.{s}", "lowerarm.{s}", "wrist.{s}", "hand.{s}"))), "l", "r"),
    "smpl": family({"pelvis": "Pelvis", "spine1": "Spine1", "spine2": "Spine2", "spine3": "Spine3", "neck": "Neck",
                    "head": "Head"},
                   dict(zip(LIMB_JOINTS, ("{s}_Hip", "{s}_Knee", "{s}_Ankle", "{s}_Foot", "{s}_Collar",
                                          "{s}_Shoulder", "{s}_Elbow", "{s}_Wrist", "{s}_Hand"))), "L", "R"),
    "daz_genesis": family({"pelvis": "hip", "spine1": "abdomenLower", "spine2": "abdomenUpper", "spine3": "chestLower",
                           "neck": "neckLower", "head": "head"},
                          dict(zip(LIMB_JOINTS, ("{s}ThighBend", "{s}Shin", "{s}Foot", "{s}Toe", "{s}Collar",
                                                 "{s}ShldrBend", "{s}ForearmBend", "{s}Hand", "{s}Mid1"))), "l", "r"),
    "humanik": {j: "Character1_" + n.split(":")[1] for j, n in MIXAMO.items()},
    "no_names": {j: f"Bone{(7 * i + 3) % 24:02d}" for i, j in enumerate(JOINT_NAMES)},
    # no toe and no finger bones (many low-poly game rigs)
    "no_toes_no_fingers": {j: ("-" if j.endswith(("_foot", "_hand")) else n.split(":")[1]) for j, n in MIXAMO.items()},
}
# unmapped bones: (name, parent joint, joint whose weights it takes half of, or None)
EXTRA = {"mixamo": [("mixamorig:LeftHandThumb1", "left_wrist", "left_wrist"),
                    ("mixamorig:RightHandThumb1", "right_wrist", "right_wrist"),
                    ("mixamorig:HeadTop_End", "head", None)],
         "rigify": [("DEF-thigh.L.001", "left_hip", "left_hip"), ("DEF-thigh.R.001", "right_hip", "right_hip")],
         # helpers that must never become joints: leaf, twist, IK / control, socket, hair and end bones
         "unreal": [("ball_leaf_l", "left_foot", None), ("thigh_twist_01_l", "left_hip", "left_hip"),
                    ("ik_foot_root", None, None), ("ik_foot_l", None, None)],
         "biped": [("Bip01 HeadNub", "head", None), ("Bip01 L UpperArmTwist", "left_shoulder", "left_shoulder")],
         "vroid": [("J_Sec_Hair1_01", "head", "head"), ("J_Adj_L_FaceEye", "head", None)],
         "character_creator": [("CC_Base_L_UpperarmTwist01", "left_shoulder", "left_shoulder"),
                               ("CC_Base_NeckTwist02", "neck", "neck")],
         "sketchfab": [("Head_end_25", "head", None), ("Left thumb1_26", "left_wrist", "left_wrist")],
         "no_names": [("Bone24", "left_wrist", "left_wrist"), ("Bone25", "head", None)],
         "daz_genesis": [("lThighTwist", "left_hip", "left_hip"), ("rShldrTwist", "right_shoulder", "right_shoulder"),
                         ("neckUpper", "neck", "neck")],
         "kaykit": [("kneeIK.l", None, None), ("control-toe-roll.l", None, None), ("handslot.l", "left_hand", None)],
         "blender_lr": [("MCH-foot_ik.L", None, None), ("thigh_twist.L", "left_hip", "left_hip")]}
TEX = 32  # texture: pixel (x, y) = (x / 31, y / 31, 0.25), a ramp bilinear sampling reproduces exactly

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


def build_rigged_human(rider, scheme, texture=None, a_pose_deg=0.0, drop=(), pelvis_drop=0.0):
    """The rider as a skinned mesh + armature in the current (empty) scene; returns (armature, mesh).
    scheme: a FAMILIES key.  drop: joints that get no bone (as in rigs with fewer spine bones, no neck,
    no collars): their weights go to the parent joint's bone and their children hang from it."""
    from mathutils import Matrix, Vector

    from addon.core.frames import to_blender
    names = FAMILIES[scheme]
    drop = set(drop) | {j for j, n in names.items() if n == "-"}

    def kept(j):  # the joint itself, else its nearest ancestor with a bone
        while j >= 0 and JOINT_NAMES[j] in drop:
            j = PARENTS[j]
        return j
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
        if name in drop:
            continue
        kids = [c for c, p in enumerate(PARENTS) if p == j]
        if kids:
            c = first_child.get(j, kids[0])
            while JOINT_NAMES[c] in drop and c in PARENTS:  # the segment runs on to the next joint with a bone
                c = PARENTS.index(c)
            tail = J[c]
        else:  # a leaf: along its parent segment
            d = J[j] - J[PARENTS[j]]
            tail = J[j] + 0.05 * d / np.linalg.norm(d)
        b = eb.new(names[name])
        b.head, b.tail = Vector(J[j].tolist()), Vector(tail.tolist())
        if PARENTS[j] >= 0:
            b.parent = eb[names[JOINT_NAMES[kept(PARENTS[j])]]]
    for name, parent, _ in EXTRA.get(scheme, ()):
        b = eb.new(name)
        if parent is None:  # an IK / control bone at the root, beside a foot
            b.head, b.tail = Vector((0.1, 0.3, 0.05)), Vector((0.1, 0.3, 0.25))
            continue
        p = eb[names[parent]]
        b.head, b.tail = p.head.copy(), p.head + (p.tail - p.head) * 0.5
        b.parent = p
    if pelvis_drop:  # a game rig's hips bone rooted at the crotch, below the hip joints
        eb[names["pelvis"]].head.z -= pelvis_drop
    bpy.ops.object.mode_set(mode="OBJECT")
    W = rider.weights.double().numpy().copy()
    groups = {}
    for j, name in enumerate(JOINT_NAMES):
        groups.setdefault(names[JOINT_NAMES[kept(j)]], np.zeros(len(W)))
        groups[names[JOINT_NAMES[kept(j)]]] += W[:, j]
    for name, _, share in EXTRA.get(scheme, ()):
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


def export_mesh_only(rider, path):
    """An unrigged person: the same mesh, no armature."""
    from addon.core.frames import to_blender
    me = bpy.data.meshes.new("statue")
    me.from_pydata(to_blender(rider.vertices.double().numpy()).tolist(), [], rider.faces.numpy().tolist())
    me.update()
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("statue", me))
    export(path)


def export_chain(path):
    """A non-humanoid rig: a 3-bone chain (a tail, a crane arm) skinning a column of boxes."""
    from mathutils import Vector
    arm = bpy.data.objects.new("chain", bpy.data.armatures.new("chain"))
    bpy.context.scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    prev = None
    for k in range(3):
        b = arm.data.edit_bones.new(f"Bone.{k:03d}")
        b.head, b.tail = Vector((0, 0, 0.5 * k)), Vector((0, 0, 0.5 * (k + 1)))
        b.parent = prev
        prev = b
    bpy.ops.object.mode_set(mode="OBJECT")
    verts = [(x, y, z) for z in np.linspace(0, 1.5, 7) for x in (-0.1, 0.1) for y in (-0.1, 0.1)]
    faces = [(4 * i + a, 4 * i + b, 4 * i + 4 + b, 4 * i + 4 + a) for i in range(6) for a, b in ((0, 1), (1, 3), (3, 2), (2, 0))]
    me = bpy.data.meshes.new("column")
    me.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new("column", me)
    bpy.context.scene.collection.objects.link(obj)
    for k in range(3):
        obj.vertex_groups.new(name=f"Bone.{k:03d}").add([i for i, v in enumerate(verts) if 0.5 * k <= v[2] <= 0.5 * (k + 1)], 1.0, "REPLACE")
    obj.modifiers.new("Armature", "ARMATURE").object = arm
    obj.parent = arm
    export(path)


def with_required_extension(src, dst, ext):
    """A copy of a .glb whose JSON says it requires glTF extension `ext` (as a compressed file's does)."""
    data = open(src, "rb").read()
    n = struct.unpack_from("<I", data, 12)[0]
    g = json.loads(data[20:20 + n])
    g["extensionsUsed"] = sorted(set(g.get("extensionsUsed", [])) | {ext})
    g["extensionsRequired"] = [ext]
    js = json.dumps(g).encode()
    js += b" " * (-len(js) % 4)
    rest = data[20 + n:]
    out = b"glTF" + struct.pack("<II", 2, 12 + 8 + len(js) + len(rest)) + struct.pack("<II", len(js), 0x4E4F534A) + js + rest
    open(dst, "wb").write(out)
    return dst


def import_here(path, rider_id="here"):
    """The Blender half in this process (the bpy module): (arrays, meta)."""
    from addon.core.rider import rider_rig
    from addon.core.curation.importers import import_model
    from addon.core.scene import reset_scene
    reset_scene()
    return rider_rig.rider_from_objects(import_model(str(path)), rider_id, os.path.basename(path))


def nearest(a, b):
    """Distance to, and index of, the nearest row of b for every row of a."""
    a, b = torch.as_tensor(np.asarray(a, np.float64)), torch.as_tensor(np.asarray(b, np.float64))
    res = [torch.cdist(c, b).min(1) for c in a.split(2048)]
    return torch.cat([r.values for r in res]).numpy(), torch.cat([r.indices for r in res]).numpy()


def cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "splatting", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, env=dict(os.environ, PYTHONPATH=os.pathsep.join(
                              [ROOT] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]),
                              OMP_WAIT_POLICY="PASSIVE"), **kw)


def meshopt_compressed(src, dst, mo):
    """A copy of a Blender-exported .glb with its vertex attributes and triangle indices compressed by
    meshoptimizer (`mo`, the package) as EXT_meshopt_compression (modes ATTRIBUTES and TRIANGLES, no filter),
    the compressed bytes in a second buffer and the first one a fallback without bytes, as gltfpack -c writes."""
    data = open(src, "rb").read()
    n = struct.unpack_from("<I", data, 12)[0]
    g = json.loads(data[20:20 + n])
    blob = data[20 + n + 8:]
    sizes = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
    comp = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
    role = {}
    for m in g["meshes"]:
        for p in m["primitives"]:
            for a in p["attributes"].values():
                role[a] = "ATTRIBUTES"
            if "indices" in p:
                role[p["indices"]] = "TRIANGLES"
    plain, packed = bytearray(), bytearray()
    for i, bv in enumerate(g["bufferViews"]):
        raw = blob[bv.get("byteOffset", 0):bv.get("byteOffset", 0) + bv["byteLength"]]
        acc = next((k for k, a in enumerate(g["accessors"]) if a.get("bufferView") == i and k in role), None)
        if acc is None:  # images, inverse bind matrices: as they were, in the plain buffer
            plain.extend(b"\0" * (-len(plain) % 4))
            bv.update(buffer=0, byteOffset=len(plain))
            plain.extend(raw)
            continue
        a = g["accessors"][acc]
        stride = sizes[a["type"]] * comp[a["componentType"]]
        if role[acc] == "ATTRIBUTES":
            enc = mo.encode_vertex_buffer(np.frombuffer(raw, np.uint8).reshape(a["count"], stride), a["count"], stride)
        else:
            idx = np.frombuffer(raw, {2: np.uint16, 4: np.uint32}[stride]).astype(np.uint32)
            enc = mo.encode_index_buffer(idx, a["count"], int(idx.max()) + 1)  # decoded at any index size
        packed.extend(b"\0" * (-len(packed) % 4))
        ext = {"buffer": 1, "byteOffset": len(packed), "byteLength": len(enc), "byteStride": stride,
               "count": a["count"], "mode": role[acc]}
        packed.extend(enc)
        bv.update(buffer=0, byteOffset=0, extensions={"EXT_meshopt_compression": ext})  # bytes only in buffer 1
        if role[acc] == "ATTRIBUTES":
            bv["byteStride"] = stride
    plain.extend(b"\0" * (-len(plain) % 4))
    packed.extend(b"\0" * (-len(packed) % 4))
    fallback = max([len(plain)] + [bv["byteLength"] for bv in g["bufferViews"]])
    g["buffers"] = [{"byteLength": fallback, "extensions": {"EXT_meshopt_compression": {"fallback": True}}},
                    {"byteLength": len(packed)}]
    # a GLB has one binary chunk: buffer 1's bytes follow the plain ones in it, buffer 0 is that chunk
    g["buffers"][0]["byteLength"] = len(plain) + len(packed)
    for bv in g["bufferViews"]:
        e = (bv.get("extensions") or {}).get("EXT_meshopt_compression")
        if e:
            e.update(buffer=0, byteOffset=len(plain) + e["byteOffset"])
    g["buffers"] = g["buffers"][:1]
    del g["buffers"][0]["extensions"]
    g["extensionsUsed"] = sorted(set(g.get("extensionsUsed", [])) | {"EXT_meshopt_compression"})
    g["extensionsRequired"] = sorted(set(g.get("extensionsRequired", [])) | {"EXT_meshopt_compression"})
    js = json.dumps(g).encode()
    js += b" " * (-len(js) % 4)
    body = bytes(plain + packed)
    out = (b"glTF" + struct.pack("<II", 2, 12 + 8 + len(js) + 8 + len(body)) + struct.pack("<II", len(js), 0x4E4F534A)
           + js + struct.pack("<II", len(body), 0x004E4942) + body)
    open(dst, "wb").write(out)
    return dst


def quantized(src, dst):
    """A copy of a Blender-exported .glb under KHR_mesh_quantization (required): texture coordinates as
    normalized unsigned shorts and normals as normalized bytes (padded to 4), positions kept as floats."""
    data = open(src, "rb").read()
    n = struct.unpack_from("<I", data, 12)[0]
    g = json.loads(data[20:20 + n])
    blob = bytearray(data[20 + n + 8:])
    done = set()
    for m in g["meshes"]:
        for p in m["primitives"]:
            for key, acc_i in p["attributes"].items():
                if acc_i in done or not (key.startswith("TEXCOORD") or key == "NORMAL"):
                    continue
                done.add(acc_i)
                a = g["accessors"][acc_i]
                bv = g["bufferViews"][a["bufferView"]]
                k = 2 if key.startswith("TEXCOORD") else 3
                x = np.frombuffer(bytes(blob[bv.get("byteOffset", 0):bv.get("byteOffset", 0) + bv["byteLength"]]),
                                  np.float32).reshape(-1, k)
                if k == 2:
                    q = np.round(np.clip(x, 0, 1) * 65535).astype("<u2")
                    raw, stride, ct = q.tobytes(), 4, 5123
                else:
                    q = np.zeros((len(x), 4), np.int8)
                    q[:, :3] = np.round(np.clip(x, -1, 1) * 127)
                    raw, stride, ct = q.tobytes(), 4, 5120
                blob.extend(b"\0" * (-len(blob) % 4))
                g["bufferViews"].append({"buffer": 0, "byteOffset": len(blob), "byteLength": len(raw), "byteStride": stride,
                                         "target": 34962})
                blob.extend(raw)
                a.update(bufferView=len(g["bufferViews"]) - 1, componentType=ct, normalized=True)
                a.pop("min", None), a.pop("max", None)
    blob.extend(b"\0" * (-len(blob) % 4))
    g["buffers"] = [{"byteLength": len(blob)}]
    g["extensionsUsed"] = sorted(set(g.get("extensionsUsed", [])) | {"KHR_mesh_quantization"})
    g["extensionsRequired"] = sorted(set(g.get("extensionsRequired", [])) | {"KHR_mesh_quantization"})
    js = json.dumps(g).encode()
    js += b" " * (-len(js) % 4)
    open(dst, "wb").write(b"glTF" + struct.pack("<II", 2, 12 + 8 + len(js) + 8 + len(blob))
                          + struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(blob), 0x004E4942)
                          + bytes(blob))
    return dst

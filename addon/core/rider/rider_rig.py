"""A user's rigged human (glTF / FBX / the open scene) -> the arrays of an imported rider (bpy side).

`rider_from_objects` reads one armature and the meshes skinned to it and returns what
cyclist_formats.rider_file stores: the T-posed mesh in the canonical frame, the 24 SMPL joints, per-vertex
weights over those joints and per-vertex colours.  Steps:

1. The rig: the armature whose bone names map to the 24 SMPL joints (cyclist_formats.bone_map: Mixamo,
   Rigify DEF-, ...), and the meshes deformed by it (Armature modifier + vertex groups, or parented to
   one of its bones).  No armature or no skinned mesh -> "unrigged"; names that do not map -> the
   bone_map error naming the joints it could not find.
2. Body frame: up = Blender's +Z (the importers' convention) unless the spine is far from it, then
   the spine; right = left -> right hips and shoulders (so the facing direction of the file does not
   matter); forward = up x right.
3. T-pose: SMPL's zero pose has the arms straight out sideways and the legs straight down; the IK and
   the built-in motions assume it.  An A-pose (or any rest pose off by more than SWING_MIN_DEG) is
   turned into it by posing the armature in Blender (upper arms, then forearms, thighs, then shins swung
   onto the T directions about their heads) and taking Blender's own deformed mesh as the new rest mesh.
   LBS from that rest then matches Blender's posing of the original rig exactly where one bone
   dominates and approximately where weights blend across a swung joint (docs/rider_import.md).
4. Weights: each vertex group of a deforming bone goes to its bone's joint, an unmapped bone's to its
   nearest mapped ancestor (the joint whose transform Blender gives it when its own pose is identity),
   normalised per vertex as Blender's Armature modifier does.  Vertices with no weight copy their nearest
   weighted vertex's weights.
5. Colours (rider_colours.py): per material, the image texture feeding the Base Color (sampled bilinearly at each corner's
   UV, averaged per vertex), a colour attribute, or the flat base colour.  A texture whose image is
   missing or unreadable is an error (not a silent grey).  Textured faces also keep their corner UVs
   and the texture itself (the rider file's texture layer), which the avatar's training renders draw.
"""
import math
import os

import bpy
import numpy as np
from mathutils import Matrix, Vector

from ..contract import UserError, bone_map
from .rider_colours import lone_texture, object_colors
from .rider_helpers import helper_faces

SWING_MIN_DEG = 1.0
# segment (joint -> child joint) and its T-pose direction in the canonical frame (left is -Z)
T_POSE_PASSES = (
    {"left_shoulder": ("left_elbow", (0, 0, -1)), "right_shoulder": ("right_elbow", (0, 0, 1)),
     "left_hip": ("left_knee", (0, -1, 0)), "right_hip": ("right_knee", (0, -1, 0))},
    {"left_elbow": ("left_wrist", (0, 0, -1)), "right_elbow": ("right_wrist", (0, 0, 1)),
     "left_knee": ("left_ankle", (0, -1, 0)), "right_knee": ("right_ankle", (0, -1, 0))},
)
UP_TOLERANCE_DEG = 30.0
MIN_HEIGHT_M, MAX_HEIGHT_M = 0.5, 2.6
# a size outside MIN..MAX read in another unit when that makes it PLAUSIBLE_M tall (most likely first)
# (feet are not guessed: a stylised figure 3-5 units tall would become a child that cannot reach the pedals)
UNIT_GUESSES = ((0.01, "centimetres"), (0.001, "millimetres"), (0.0254, "inches"), (0.1, "decimetres"),
                (100.0, "metres shrunk 100 times (a centimetre conversion applied twice)"))
PLAUSIBLE_M = (1.0, 2.2)
PELVIS_LOW, PELVIS_ABOVE_HIPS = 0.015, 0.008  # of the ankle-to-head height (SMPL: pelvis 1 cm above hips)
END_HAND_FRACTION = 0.47  # SMPL's hand joint (knuckles) along wrist -> fingertips
CUTOUT_ALPHA = 0.5     # faces whose texture alpha averages below this are invisible: dropped
LEG_M = 0.82          # an adult's leg, hip joint to ankle (a 1.75 m person)
MIN_LEG_SHARE = 0.15  # legs under 15 % of the height: not a person (a chibi figure's are ~25 %)


def _joints():
    return bone_map.SMPL_JOINTS


def _m2np(m):
    return np.array([list(r) for r in m], dtype=np.float64)


def _np2m(a):
    return Matrix([list(map(float, r)) for r in a])


# ---------------------------------------------------------------- 1. the rig

def _deformed_by(obj, arm):
    if obj.type != "MESH":
        return False
    if obj.parent == arm and obj.parent_type == "BONE" and obj.parent_bone in arm.data.bones:
        return True
    mods = [m for m in obj.modifiers if m.type == "ARMATURE" and m.object == arm]
    return bool(mods) and any(g.name in arm.data.bones for g in obj.vertex_groups)


def _skeleton(arm):
    """The armature's bones for bone_map.map_skeleton: names, parents, rest heads/tails in world space."""
    A = arm.matrix_world
    return [{"name": b.name, "parent": b.parent.name if b.parent else None, "deform": bool(b.use_deform),
             "head": list(A @ b.head_local), "tail": list(A @ b.tail_local)} for b in arm.data.bones]


def find_rig(objects, what):
    """(armature, its skinned meshes, bone_map.Mapping) among `objects`; UserError otherwise."""
    objects = list(objects)
    meshes = [o for o in objects if o.type == "MESH"]
    arms = [o for o in objects if o.type == "ARMATURE"]
    if not meshes:
        raise UserError(f"{what}: no mesh in it; a rider needs a rigged human mesh")
    if not arms:
        raise UserError(f"{what}: unrigged mesh (no armature): rig the human first (e.g. Mixamo or Rigify), "
                        f"then import it")
    first_error, mapped = None, []
    for arm in sorted(arms, key=lambda a: -len(a.data.bones)):
        skinned = [o for o in objects if _deformed_by(o, arm)]
        z = [(o.matrix_world @ Vector(c)).z for o in skinned for c in o.bound_box]
        try:
            m = bone_map.map_skeleton(_skeleton(arm), f"{what}: armature '{arm.name}'",
                                      (min(z), max(z)) if z else None)
        except UserError as e:
            first_error = first_error or e
            continue
        mapped.append((arm, m))
    if not mapped:
        raise first_error
    arm, m = mapped[0]
    skinned = [o for o in objects if _deformed_by(o, arm)]
    if not skinned:
        raise UserError(f"{what}: unrigged mesh: no mesh is skinned to armature '{arm.name}' "
                        f"(no Armature modifier with bone vertex groups, no bone parent)")
    return arm, skinned, m


# ---------------------------------------------------------------- 2./3. frame and T-pose

def _posed_heads(arm, bone_of, placed=None):
    """World positions (24,3) of the joints at the armature's current pose: a mapped bone's head, or a
    placed joint (placed: {joint: (bone, offset in that bone's rest space)}) riding on its bone."""
    A = arm.matrix_world
    out = []
    for j in _joints():
        if placed and j in placed:
            b, off = placed[j]
            out.append(list(A @ arm.pose.bones[b].matrix @ off))
        else:
            out.append(list(A @ arm.pose.bones[bone_of[j]].head))
    return np.array(out, np.float64)


def _placed_offsets(arm, virtual):
    """{joint: (bone, offset)}: a placed joint's rest position in its bone's rest space."""
    A = arm.matrix_world
    return {j: (b, (A @ arm.data.bones[b].matrix_local).inverted() @ Vector([float(x) for x in p]))
            for j, (b, p) in virtual.items()}


def _lift_pelvis(heads, M, pelvis_bone):
    """{"pelvis": (its bone, position)} when the pelvis bone's head sits more than PELVIS_LOW of the body
    below the hip joints (game rigs root the hips at the crotch): SMPL's pelvis joint is just above
    the hips (by PELVIS_ABOVE_HIPS of the body), and the IK seats that joint above the saddle.  The
    joint still drives its bone and its weights; only the point it turns about moves."""
    J = {n: i for i, n in enumerate(_joints())}
    up = M[1]
    mid = (heads[J["left_hip"]] + heads[J["right_hip"]]) / 2
    body = float((heads[J["head"]] - (heads[J["left_ankle"]] + heads[J["right_ankle"]]) / 2) @ up)
    below = float((mid - heads[J["pelvis"]]) @ up)
    if body <= 0 or below <= PELVIS_LOW * body:
        return {}
    return {"pelvis": (pelvis_bone, heads[J["pelvis"]] + up * (below + PELVIS_ABOVE_HIPS * body))}


def _end_points(arm, bone, skinned):
    """World rest positions of the vertices `bone` and the bones below it weigh most."""
    names = {bone} | {c.name for c in arm.data.bones[bone].children_recursive}
    out = []
    for obj in skinned:
        groups = {g.index for g in obj.vertex_groups if g.name in names}
        if obj.parent_type == "BONE" and obj.parent_bone in names:
            out.append(_evaluated_world_vertices(obj))
        elif groups:
            co = _evaluated_world_vertices(obj)
            sel = [v.index for v in obj.data.vertices if sum(g.weight for g in v.groups if g.group in groups) > 0.5]
            out.append(co[sel])
    return np.concatenate(out) if out else np.zeros((0, 3))


def _derive_ends(arm, mapping, skinned, M, heads):
    """Toe and hand joints for limbs without toe or finger bones, from the mesh: a toe 3/4 of the way
    from the ankle to the foot's most forward vertex, a hand (SMPL's knuckles) END_HAND_FRACTION of the
    way from the wrist to the hand's farthest vertex along the forearm; the bone's tail, else a step
    along the limb, where the mesh says nothing (glTF bone tails are the importer's guess)."""
    J = {n: i for i, n in enumerate(_joints())}
    out = {}
    for j, v in mapping.virtual.items():
        if v[0] not in ("toe", "hand"):
            continue
        bone, side = v[1], j.split("_")[0]
        if v[0] == "toe":
            base, d, frac = heads[J[f"{side}_ankle"]], M[0], 0.75
            step = 0.12 * np.linalg.norm(heads[J[f"{side}_knee"]] - base)
        else:
            base, e = heads[J[f"{side}_wrist"]], heads[J[f"{side}_elbow"]]
            d = (base - e) / max(np.linalg.norm(base - e), 1e-12)
            frac, step = END_HAND_FRACTION, 0.35 * np.linalg.norm(base - e)
        pts = _end_points(arm, bone, skinned)
        far = pts[np.argmax((pts - base) @ d)] if len(pts) else None
        if far is None or (far - base) @ d <= 0:
            tail = np.array(list(arm.matrix_world @ arm.data.bones[bone].tail_local))
            far = tail if (tail - base) @ d > 0 else base + d * step / frac
        out[j] = (bone, base + frac * (far - base))
    return out


def body_frame(heads):
    """World -> canonical rotation (rows: forward, up, right) from world joint positions.

    Up is Blender's +Z (both importers bring glTF's Y-up and FBX's axes to Z-up) when the spine
    (pelvis -> neck) is within UP_TOLERANCE_DEG of it, so a spine leaning a little is kept as it is
    modelled; a file lying down (turned by a right angle) takes the world axis the spine is as near,
    else the spine itself.  Right comes from the hips and shoulders."""
    J = {n: i for i, n in enumerate(_joints())}
    spine = heads[J["neck"]] - heads[J["pelvis"]]
    lr = (heads[J["right_hip"]] - heads[J["left_hip"]]) + (heads[J["right_shoulder"]] - heads[J["left_shoulder"]])
    if np.linalg.norm(spine) < 1e-9 or np.linalg.norm(lr) < 1e-9:
        raise UserError("the skeleton is degenerate: pelvis and neck (or left and right hips) coincide")
    spine = spine / np.linalg.norm(spine)
    # a file lying down is nearly always one turned by a right angle (Y-up read as Z-up, an exporter's
    # axis setting): up is the world axis the spine is within UP_TOLERANCE_DEG of, the spine itself otherwise
    k = int(np.argmax(np.abs(spine)))
    axis = np.zeros(3)
    axis[k] = np.sign(spine[k])
    up = axis if spine @ axis > math.cos(math.radians(UP_TOLERANCE_DEG)) else spine
    right = lr - up * (lr @ up)
    if np.linalg.norm(right) < 1e-6 * np.linalg.norm(lr):
        raise UserError("the skeleton's left-right axis (hips, shoulders) is parallel to its spine")
    right /= np.linalg.norm(right)
    return np.stack([np.cross(up, right), up, right])


def _check_humanoid(heads, M, what):
    """Joint heights along the body's up axis must be ordered like a standing person's."""
    J = {n: i for i, n in enumerate(_joints())}
    y = heads @ M[1]
    order = [("head", "neck"), ("neck", "pelvis"), ("pelvis", "left_knee"), ("pelvis", "right_knee"),
             ("left_knee", "left_ankle"), ("right_knee", "right_ankle")]
    wrong = [f"{a} below {b}" for a, b in order if not y[J[a]] > y[J[b]]]
    if wrong:
        raise UserError(f"{what}: the mapped bones do not stand like a person ({', '.join(wrong)}): "
                        f"not a humanoid rest pose")


def _swing(a, b):
    """Smallest rotation (3,3) turning unit vector a onto unit vector b, and its angle (radians)."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(a @ b)
    if s < 1e-12:
        return np.eye(3), 0.0 if c > 0 else math.pi
    k = axis / s
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    ang = math.atan2(s, c)
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K, ang


def to_t_pose(arm, bone_of, M, placed=None):
    """Pose the armature so the limbs lie on the T-pose directions; returns {joint: swing degrees}."""
    J = {n: i for i, n in enumerate(_joints())}
    A = arm.matrix_world
    A_inv = A.inverted()
    swings = {}
    for targets in T_POSE_PASSES:
        heads = _posed_heads(arm, bone_of, placed)
        for joint, (child, direction) in targets.items():
            cur = heads[J[child]] - heads[J[joint]]
            cur /= np.linalg.norm(cur)
            want = M.T @ np.asarray(direction, float)
            R, ang = _swing(cur, want)
            swings[joint] = round(math.degrees(ang), 3)
            if math.degrees(ang) < SWING_MIN_DEG:
                continue
            p = Vector(heads[J[joint]].tolist())
            E = Matrix.Translation(p) @ _np2m(R).to_4x4() @ Matrix.Translation(-p)  # world turn about the head
            pb = arm.pose.bones[bone_of[joint]]
            pb.matrix = A_inv @ E @ A @ pb.matrix
        bpy.context.view_layer.update()
    return swings


# ---------------------------------------------------------------- 4. mesh and weights

def _bone_joint_index(arm, bone_of, heads_rest):
    """Bone name -> SMPL joint index: its own joint, its nearest mapped ancestor's, else the nearest joint."""
    J = {n: i for i, n in enumerate(_joints())}
    of_bone = {b: J[j] for j, b in bone_of.items() if b}
    out = {}
    for bone in arm.data.bones:
        k = bone
        while k is not None and k.name not in of_bone:
            k = k.parent
        if k is not None:
            out[bone.name] = of_bone[k.name]
        else:
            h = np.array(list(arm.matrix_world @ bone.head_local))
            out[bone.name] = int(np.argmin(np.linalg.norm(heads_rest - h, axis=1)))
    return out


def _object_weights(obj, arm, bone_joint):
    n = len(obj.data.vertices)
    W = np.zeros((n, len(_joints())))
    if obj.parent == arm and obj.parent_type == "BONE" and not any(
            m.type == "ARMATURE" and m.object == arm for m in obj.modifiers):
        W[:, bone_joint[obj.parent_bone]] = 1.0
        return W
    deform = {b.name for b in arm.data.bones if b.use_deform}
    group_joint = {g.index: bone_joint[g.name] for g in obj.vertex_groups if g.name in deform}
    for v in obj.data.vertices:
        for g in v.groups:
            j = group_joint.get(g.group)
            if j is not None and g.weight > 0:
                W[v.index, j] += g.weight
    return W


def _evaluated_world_vertices(obj):
    """Blender's own deformed vertices (world), with the armature only (other modifiers off)."""
    saved = [(m, m.show_viewport) for m in obj.modifiers if m.type != "ARMATURE"]
    for m, _ in saved:
        m.show_viewport = False
    try:
        bpy.context.view_layer.update()
        dg = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(dg)
        me = ev.to_mesh()
        try:
            if len(me.vertices) != len(obj.data.vertices):
                raise UserError(f"object '{obj.name}': its deformation changes the vertex count")
            co = np.empty(len(me.vertices) * 3)
            me.vertices.foreach_get("co", co)
            Mw = _m2np(ev.matrix_world)
        finally:
            ev.to_mesh_clear()
    finally:
        for m, s in saved:
            m.show_viewport = s
    co = co.reshape(-1, 3)
    return co @ Mw[:3, :3].T + Mw[:3, 3]


def _fill_unweighted(W, V):
    """Rows with no weight take the weights of the nearest weighted vertex; returns the count filled."""
    s = W.sum(1)
    empty = np.flatnonzero(s <= 0)
    have = np.flatnonzero(s > 0)
    if len(empty) == 0:
        return 0
    step = max(1, 4_000_000 // max(1, len(have)))  # ~100 MB of distances at a time
    for chunk in np.array_split(empty, len(empty) // step + 1):
        if len(chunk):
            d = ((V[chunk, None, :] - V[None, have, :]) ** 2).sum(-1)
            W[chunk] = W[have[d.argmin(1)]]
    return len(empty)


# ---------------------------------------------------------------- the whole import

def _triangles(me):
    """Triangles as vertex indices (T,3) and as loop indices (T,3)."""
    me.calc_loop_triangles()
    t = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("vertices", t)
    lo = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("loops", lo)
    return t.reshape(-1, 3), lo.reshape(-1, 3)


def rider_from_objects(objects, rider_id, what, height_m=None, restore=True, model_dir=None):
    """(arrays for rider_file.write_rider_file, meta) from the scene objects of one rigged human.

    height_m rescales the body to that soles-to-crown height; otherwise its size must already be a
    person's (MIN_HEIGHT_M..MAX_HEIGHT_M metres).  The armature's pose is reset to its rest pose for the
    import and put back afterwards when `restore`."""
    arm, skinned, mapping = find_rig(objects, what)
    bone_of = {j: b for j, b in mapping.bone_of.items() if b}
    saved = {pb.name: pb.matrix_basis.copy() for pb in arm.pose.bones}
    saved_position = arm.data.pose_position
    try:
        arm.data.pose_position = "POSE"
        for pb in arm.pose.bones:
            pb.matrix_basis = Matrix.Identity(4)
        bpy.context.view_layer.update()
        placed = _placed_offsets(arm, {j: v for j, v in mapping.virtual.items() if v[0] not in ("toe", "hand")})
        toes = [j for j, v in mapping.virtual.items() if v[0] in ("toe", "hand")]
        for j in toes:  # a stand-in until the body frame is known
            placed[j] = (mapping.virtual[j][1], Vector((0.0, 0.0, 0.0)))
        heads_rest = _posed_heads(arm, bone_of, placed)
        M = body_frame(heads_rest)
        _check_humanoid(heads_rest, M, what)
        if toes:
            placed.update(_placed_offsets(arm, _derive_ends(arm, mapping, skinned, M, heads_rest)))
        lifted = _lift_pelvis(heads_rest, M, bone_of["pelvis"])
        placed.update(_placed_offsets(arm, lifted))
        heads_rest = _posed_heads(arm, bone_of, placed)
        bone_joint = _bone_joint_index(arm, bone_of, heads_rest)
        rest_deform = {}
        swings = to_t_pose(arm, bone_of, M, placed)
        A, A_inv = arm.matrix_world, arm.matrix_world.inverted()
        for j in _joints():  # each joint's bone's world deformation rest -> T-pose (identity for a T-posed rig)
            pb = arm.pose.bones[bone_of[j] if j in bone_of else placed[j][0]]
            rest_deform[j] = _m2np(A @ pb.matrix @ pb.bone.matrix_local.inverted() @ A_inv).tolist()
        heads_t = _posed_heads(arm, bone_of, placed)
        V, F, W, C, UV, FT, n_filled = [], [], [], [], [], [], 0
        images, base, missing, keep_parts, weighted = {}, 0, [], [], []
        assumed_texture = lone_texture([o for o in skinned if o.type == "MESH"], model_dir)
        for obj in skinned:
            v = _evaluated_world_vertices(obj)
            w = _object_weights(obj, arm, bone_joint)
            weighted.append((int((w.sum(1) > 0).sum()), len(w), obj.name))
            tri, tri_loops = _triangles(obj.data)
            col, loop_uv, loop_tex, loop_alpha = object_colors(obj, what, images, [model_dir] if model_dir else [],
                                                               missing)
            keep_parts.append(loop_alpha[tri_loops].mean(1) >= CUTOUT_ALPHA)
            V.append(v)
            F.append(tri + base)
            W.append(w)
            C.append(col)
            UV.append(loop_uv[tri_loops])
            FT.append(loop_tex[tri_loops[:, 0]])  # a triangle lies in one polygon: one material
            base += len(v)
    finally:
        if restore:
            for pb in arm.pose.bones:
                pb.matrix_basis = saved[pb.name]
            arm.data.pose_position = saved_position
            bpy.context.view_layer.update()
    V, F, W, C = np.concatenate(V), np.concatenate(F), np.concatenate(W), np.concatenate(C)
    # the body (the largest skinned mesh) and the whole must be mostly weighted; a piece weighted sparsely
    # or not at all (a cape pinned at its collar, a strap) takes its vertices' nearest weighted ones
    wc, n, name = max(weighted, key=lambda t: t[1])
    if wc * 2 < n or sum(t[0] for t in weighted) * 2 < len(W):
        wc, n, name = min(weighted, key=lambda t: t[0] / t[1])
        raise UserError(f"{what}: unrigged mesh: object '{name}' has bone weights on only {wc} of {n} vertices")
    n_filled = _fill_unweighted(W, V)
    UV, FT, keep = np.concatenate(UV), np.concatenate(FT), np.concatenate(keep_parts)
    n_cut = int((~keep).sum())
    if n_cut == len(keep):
        raise UserError(f"{what}: every face is transparent (texture alpha below {CUTOUT_ALPHA})")
    helpers = helper_faces(V, F, UV, FT, W / W.sum(1, keepdims=True)) & keep
    n_helper = int(helpers.sum())
    keep &= ~helpers
    if not keep.all():  # invisible faces (alpha cut-outs) and hidden helper geometry are not the person
        F, UV, FT = F[keep], UV[keep], FT[keep]
        used = np.unique(F)
        new_index = np.full(len(V), -1, np.int64)
        new_index[used] = np.arange(len(used))
        V, W, C, F = V[used], W[used], C[used], new_index[F]
    W /= W.sum(1, keepdims=True)
    # world -> canonical: rotate by M, scale, soles on Y = 0, pelvis on the Y axis
    Vc, Jc = V @ M.T, heads_t @ M.T
    height = float(Vc[:, 1].max() - Vc[:, 1].min())
    if height <= 0:
        raise UserError(f"{what}: the mesh is flat along the body's up axis")
    J = {n: i for i, n in enumerate(_joints())}
    leg = float(np.mean([np.linalg.norm(Jc[J[f"{s}_hip"]] - Jc[J[f"{s}_ankle"]]) for s in ("left", "right")]))
    scale, size = plausible_scale(height, leg, height_m, what)
    Vc, Jc = Vc * scale, Jc * scale
    shift = np.array([-Jc[0, 0], -Vc[:, 1].min(), -Jc[0, 2]])
    Vc, Jc = Vc + shift, Jc + shift
    canon = np.eye(4)
    canon[:3, :3], canon[:3, 3] = scale * M, shift
    meta = {
        "id": rider_id, "source": what, "scheme": mapping.scheme, "armature": arm.name,
        "objects": [o.name for o in skinned], "bone_map": dict(bone_of),
        "placed_joints": {j: placed[j][0] for j in _joints() if j not in bone_of},
        "moved_joints": sorted(j for j in placed if j in bone_of),
        "joint_source": dict(mapping.how),
        "rest_pose": "T" if max(swings.values()) < 10.0 else "A" if all(
            abs(swings[s] - 45) < 40 for s in ("left_shoulder", "right_shoulder")) else "other",
        "swings_deg": swings, "height_m": round(float(Vc[:, 1].max()), 4), "scale": scale, "size": size,
        "canonical_from_world": canon.tolist(), "t_pose_deform_world": rest_deform,
        "unweighted_vertices_filled": int(n_filled), "textures": sorted(images),
        "missing_textures": missing, "assumed_texture": assumed_texture and os.path.basename(assumed_texture),
        "transparent_faces_dropped": n_cut, "helper_faces_dropped": n_helper,
        "blender": bpy.app.version_string,
    }
    arrays = {"vertices": Vc, "faces": F, "joints": Jc, "weights": W, "colors": C}
    if images:  # the texture layer: the training renders draw the textures themselves, not vertex colours
        arrays.update(uv=UV, face_texture=FT,
                      textures=[np.round(t * 255).astype(np.uint8) for t in images.values()])
    return arrays, meta


def plausible_scale(height, leg, height_m, what):
    """(scale to metres, what was assumed) for a body `height` tall with legs (hip joint to ankle, in the
    T-pose) `leg` long, in Blender's units after the file's own unit settings and object matrices (the
    importers apply them).  A person's size is kept; a size that is a person's in another unit (cm, mm,
    inches, dm) is read in it; otherwise (a stylised figure 3 units tall, a tiny armature with no
    unit) the legs are given an adult's length (LEG_M), which is what reaching the pedals needs.
    Refused: legs that are not a plausible share of the height (not a person)."""
    if height_m is not None:
        return float(height_m) / height, f"--height-m {float(height_m):g} given"
    share = leg / height
    if not MIN_LEG_SHARE <= share <= 0.75:
        raise UserError(f"{what}: its legs (hip to ankle) are {share:.0%} of its height: not a person's "
                        f"proportions (expected {MIN_LEG_SHARE:.0%}-75%)")
    if MIN_HEIGHT_M <= height <= MAX_HEIGHT_M:
        return 1.0, f"{height:.3g} m as in the file"
    for factor, unit in UNIT_GUESSES:
        if PLAUSIBLE_M[0] <= height * factor <= PLAUSIBLE_M[1]:
            return factor, f"{height:.4g} units in the file read as {unit} ({height * factor:.3g} m)"
    scale = LEG_M / leg
    if height * scale > MAX_HEIGHT_M * 0.95:
        scale = MAX_HEIGHT_M * 0.95 / height
    return scale, (f"{height:.4g} units in the file, no unit fits a person: legs scaled to an adult's "
                   f"({leg * scale:.2f} m hip to ankle, {height * scale:.2f} m tall)")


def pose_rig(arm, bone_of, meta, world_transforms):
    """Pose the original armature with a rider pose: world_transforms (24,4,4) are the canonical-frame
    LBS transforms of splatting.rider.kinematics.forward_kinematics (rest T-pose -> posed) for the
    rider imported from this armature.  Each mapped bone gets the deformation F^-1 T_j F D_j (F:
    canonical_from_world, D_j: the import's rest -> T-pose turn); unmapped bones keep their rest basis
    and follow their parents, as their weights do."""
    F = np.asarray(meta["canonical_from_world"], float)
    F_inv = np.linalg.inv(F)
    A, A_inv = arm.matrix_world, arm.matrix_world.inverted()
    depth = lambda b: len(arm.data.bones[b].parent_recursive)  # noqa: E731
    for pb in arm.pose.bones:
        pb.matrix_basis = Matrix.Identity(4)
    bpy.context.view_layer.update()
    order = sorted((j for j in range(len(_joints())) if bone_of.get(_joints()[j])),
                   key=lambda j: depth(bone_of[_joints()[j]]))
    for j in order:
        name = _joints()[j]
        D = np.asarray(meta["t_pose_deform_world"][name], float)
        world = F_inv @ np.asarray(world_transforms[j], float) @ F @ D
        pb = arm.pose.bones[bone_of[name]]
        pb.matrix = A_inv @ _np2m(world) @ A @ pb.bone.matrix_local
        bpy.context.view_layer.update()


def save_rider(objects, rider_id, folder, what, height_m=None, overwrite=False, model_dir=None):
    """The add-on's "Save as rider": rider_from_objects, written to <folder>/<rider_id>/rider.npz (where
    `python -m splatting` finds imported riders when folder is the project's data/imported_riders).
    Returns (path, meta)."""
    import os

    from ..contract import rider_file
    rider_file.check_rider_id(rider_id, "rider id")
    if not folder:
        raise UserError("no riders folder given (the project's data/imported_riders)")
    path = os.path.join(folder, rider_id, rider_file.FILE_NAME)
    if os.path.exists(path) and not overwrite:
        raise UserError(f"{path} exists: rider {rider_id!r} was imported before (tick Overwrite to replace it)")
    arrays, meta = rider_from_objects(objects, rider_id, what, height_m, model_dir=model_dir)
    rider_file.write_rider_file(path, meta=meta, **arrays)
    return path, meta

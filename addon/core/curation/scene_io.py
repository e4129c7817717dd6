"""The bpy side of curation: the annotator's working state lives in the scene.

- `curation_source`: the imported model joined into one mesh, in the canonical pose (Blender
  frame) after auto_curate; face attributes `articcyc_part` (automatic label) and
  `articcyc_paint` (annotator override, -1 = none).
- collection `keypoints`: one labelled empty `kp.<name>` per keypoint (drag/snap them).
- `frame`, `steering`, `crank`: the split parts (pass_index 1/2/3), `armature`: the rig.
- scene["articcyc_curation"]: the curation record (JSON) that goes into meta.json.
"""
import hashlib
import json
import os
import shutil
import tempfile

import bpy
import numpy as np
from mathutils import Matrix, Vector

from ..rig import armature as arm_mod
from .. import bike_asset
from ..frames import C, to_blender, to_canonical
from ..procedural.build import PASS_INDEX
from ..procedural.layout import KEYPOINT_NAMES, part_keypoints
from ..contract import UserError
from . import pipeline, split
from .validate import validate

SOURCE = "curation_source"
KP_COLLECTION = "keypoints"
PART_ATTR, PAINT_ATTR, HINT_ATTR = "articcyc_part", "articcyc_paint", "articcyc_hint"
CUT_ATTR = "articcyc_cut"   # faces of a fused piece: cut along the part boundaries, labelled per piece
RECORD = "articcyc_curation"
SKIPPED = "articcyc_skipped_objects"
JUNK_PAINT = 9   # painted "not the bike": left out of every part
# collision / physics proxies by the naming conventions of game engines (Unreal UCX_/UBX_/USP_/
# UCP_, Godot -col/-colonly, Unity/three.js "collider"), and helpers exporters add
_PROXY = ("ucx_", "ubx_", "usp_", "ucp_")
_PROXY_WORDS = ("collider", "collision", "-col", "_col", "colonly", "hitbox", "physics_proxy", "shadow_plane",
                "shadowcatcher", "shadow_catcher")


def _is_visible_geometry(o):
    """False for objects a viewer of the file would not see as the bike: hidden (glTF bone
    shapes, helpers), shown as wire/bounds only, or named as a collision proxy."""
    name = o.name.lower()
    if name.startswith(_PROXY) or any(w in name for w in _PROXY_WORDS):
        return False
    if o.hide_render or o.hide_viewport or o.hide_get() or o.display_type in ("WIRE", "BOUNDS"):
        return False
    for c in o.users_collection:
        if c.hide_render or c.hide_viewport or "not_exported" in c.name.lower():
            return False
    return True
PARTS = ("frame", "steering", "crank")


def _face_attr(mesh, name, values=None):
    a = mesh.attributes.get(name)
    if a is None:
        a = mesh.attributes.new(name, "INT", "FACE")
    if values is not None:
        a.data.foreach_set("value", np.asarray(values, np.int32))
    return a


def _get_face_attr(mesh, name, default=-1):
    a = mesh.attributes.get(name)
    out = np.full(len(mesh.polygons), default, np.int32)
    if a is not None and a.domain == "FACE":
        a.data.foreach_get("value", out)
    return out


def _part_name(obj):
    name = obj.name.split(".")[0].lower()
    return name if name in PARTS else None


def _hint_for(obj, use_names):
    """Per-polygon part hint from the object's name or vertex groups named like a part.  Names
    count only when at least two objects carry part names (a model that is one object called
    `crank` says nothing), vertex groups only when at least two part groups exist."""
    n = len(obj.data.polygons)
    if use_names and _part_name(obj):
        return np.full(n, PARTS.index(_part_name(obj)), np.int32)
    hint = np.full(n, -1, np.int32)
    groups = {g.index: PARTS.index(g.name.lower()) for g in obj.vertex_groups if g.name.lower() in PARTS}
    if len(set(groups.values())) >= 2:
        vlab = np.full(len(obj.data.vertices), -1, np.int32)
        for v in obj.data.vertices:
            for g in v.groups:
                if g.group in groups and g.weight > 0.5:
                    vlab[v.index] = groups[g.group]
        for p in obj.data.polygons:
            labs = vlab[list(p.vertices)]
            if labs.min() >= 0 and labs.min() == labs.max():
                hint[p.index] = labs[0]
    return hint


def join_meshes(scene=None):
    """Replace every object of the scene by one mesh `curation_source` in world coordinates
    (modifiers applied, instances realised); cameras, lights, empties are removed."""
    scene = scene or bpy.context.scene
    dg = bpy.context.evaluated_depsgraph_get()
    meshes = [o for o in scene.objects if o.type == "MESH"]
    if not meshes:
        raise UserError("no mesh objects in the scene (nothing to curate)")
    skipped = [o.name for o in meshes if not _is_visible_geometry(o)]
    meshes = [o for o in meshes if _is_visible_geometry(o)]
    if not meshes:
        raise UserError(f"all {len(skipped)} mesh object(s) are hidden or colliders (nothing to curate)")
    scene[SKIPPED] = json.dumps(skipped)
    use_names = len({_part_name(o) for o in meshes} - {None}) >= 2
    parts = []
    for o in meshes:
        me = bpy.data.meshes.new_from_object(o.evaluated_get(dg))
        me.transform(o.matrix_world)
        if len(me.polygons) == 0:
            bpy.data.meshes.remove(me)
            continue
        _face_attr(me, HINT_ATTR, _hint_for(o, use_names) if len(o.data.polygons) == len(me.polygons)
                   else np.full(len(me.polygons), -1))
        tmp = bpy.data.objects.new("_join", me)
        scene.collection.objects.link(tmp)
        for i, m in enumerate(o.material_slots):
            if i < len(me.materials) and m.material is not None:
                me.materials[i] = m.material
        parts.append(tmp)
    if not parts:
        raise UserError("the mesh objects have no faces (nothing to curate)")
    for o in list(scene.objects):
        if o not in parts:
            bpy.data.objects.remove(o, do_unlink=True)
    vl = bpy.context.view_layer
    for o in parts:
        o.select_set(True)
    vl.objects.active = parts[0]
    if len(parts) > 1:
        with bpy.context.temp_override(active_object=parts[0], selected_editable_objects=parts,
                                       object=parts[0]) if hasattr(bpy.context, "temp_override") else _nullctx():
            bpy.ops.object.join()
    src = vl.objects.active
    src.name = SOURCE
    src.data.name = SOURCE
    return src


class _nullctx:
    def __enter__(self):
        return self

    def __exit__(self, *a):
        return False


def mesh_arrays(obj):
    """(V (n,3), T (m,3), tri_poly (m,)) of a mesh object's own coordinates."""
    me = obj.data
    V = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", V)
    me.calc_loop_triangles()
    T = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("vertices", T)
    tp = np.empty(len(me.loop_triangles), np.int64)
    me.loop_triangles.foreach_get("polygon_index", tp)
    return V.reshape(-1, 3), T.reshape(-1, 3), tp


def _poly_labels(tri_labels, tri_poly, tri_area, n_poly):
    """One label per polygon: the label of most of its area."""
    out = np.full(n_poly, split.JUNK, np.int32)
    best = np.full(n_poly, -1.0)
    for lab in (split.JUNK, split.FRAME, split.STEERING, split.CRANK):
        w = np.bincount(tri_poly, weights=tri_area * (tri_labels == lab), minlength=n_poly)
        better = w > best
        out[better], best[better] = lab, w[better]
    return out


def _delete_faces(obj, mask):
    import bmesh
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[f for f in bm.faces if mask[f.index]], context="FACES")
    loose = [v for v in bm.verts if not v.link_faces]
    bmesh.ops.delete(bm, geom=loose, context="VERTS")
    bm.to_mesh(obj.data)
    bm.free()
    obj.data.update()


def read_keypoints_file(path):
    """Canonical keypoints from a JSON file: {"keypoints": {name: [x, y, z]}} (or a bare dict)."""
    try:
        with open(path) as f:
            doc = json.load(f)
    except FileNotFoundError:
        raise UserError(f"keypoints file not found: {path}") from None
    except (OSError, ValueError) as e:
        raise UserError(f"{path}: unreadable keypoints JSON ({e})") from None
    kp = doc.get("keypoints", doc) if isinstance(doc, dict) else None
    if not isinstance(kp, dict):
        raise UserError(f"{path}: expected {{\"keypoints\": {{name: [x, y, z]}}}}")
    if isinstance(doc, dict) and doc.get("frame", "canonical") != "canonical":
        raise UserError(f"{path}: keypoints must be in the canonical frame (\"frame\": \"canonical\")")
    out = {}
    for k, v in kp.items():
        if k not in KEYPOINT_NAMES:
            raise UserError(f"{path}: unknown keypoint '{k}' (known: {', '.join(KEYPOINT_NAMES)})")
        try:
            p = np.asarray(v, float)
        except (TypeError, ValueError):
            p = None
        if p is None or p.shape != (3,) or not np.all(np.isfinite(p)):
            raise UserError(f"{path}: keypoint '{k}' is not three finite numbers")
        out[k] = p
    return out


def auto_curate(wheel_diameter=pipeline.DEFAULT_WHEEL_DIAMETER, keypoints=None, source_path=None,
                from_wheel_empties=False):
    """Clean up, pose, scale, annotate and split the current scene's model.  Returns the
    pipeline Result; the scene then holds the parts, the hidden source and keypoint empties.

    Run again on a scene that already holds `curation_source` (a partial or finished curation)
    it re-derives everything from that mesh, keeping faces the annotator painted; with
    from_wheel_empties the wheel centres are the empties kp.front_axle / kp.rear_axle wherever
    the annotator put them, instead of the automatic wheel search.
    When the keypoints are incomplete the split waits (the problems say why) instead of failing."""
    scene = bpy.context.scene
    src = bpy.data.objects.get(SOURCE)
    again = src is not None
    if again:
        _clear_derived()
        src.hide_set(False)
    else:
        src = join_meshes(scene)
    wheel_centres = None
    if from_wheel_empties:
        bpy.context.view_layer.update()   # empties just moved by a script: refresh matrix_world
        inv = np.array(src.matrix_world.inverted())
        pts = []
        for name in ("front_axle", "rear_axle"):
            e = bpy.data.objects.get(f"kp.{name}")
            if e is None:
                raise UserError(f"place the wheel centre empty kp.{name} first (Place wheel centres)")
            pts.append((inv @ np.r_[np.array(e.matrix_world.translation), 1.0])[:3])
        wheel_centres = tuple(pts)
    V, T, tp = mesh_arrays(src)
    V = V @ np.array(src.matrix_world)[:3, :3].T + np.array(src.matrix_world)[:3, 3]
    src.data.transform(src.matrix_world)
    src.matrix_world = Matrix.Identity(4)
    hints_poly = _get_face_attr(src.data, HINT_ATTR)
    paint_before = _get_face_attr(src.data, PAINT_ATTR) if again else None
    res = pipeline.curate_arrays(V, T, wheel_diameter, keypoints,
                                 hints=hints_poly[tp] if (hints_poly >= 0).any() else None,
                                 wheel_centres=wheel_centres)
    area = np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1)
    plab = _poly_labels(res.labels, tp, area, len(src.data.polygons))
    c4 = np.eye(4)
    c4[:3, :3] = C
    src.data.transform(Matrix((c4 @ res.M).tolist()))
    _face_attr(src.data, PART_ATTR, plab)
    paint = np.where(hints_poly >= 0, hints_poly, -1)
    if paint_before is not None:
        paint = np.where(paint_before >= 0, paint_before, paint)
    _face_attr(src.data, PAINT_ATTR, paint)
    cut_poly = (np.bincount(tp, weights=res.cut.astype(float), minlength=len(plab)) > 0) & (paint < 0)
    _face_attr(src.data, CUT_ATTR, cut_poly.astype(np.int32))
    _delete_faces(src, (plab == split.JUNK) & (paint < 0))
    rec = dict(res.record)
    if cut_poly.any() and all(k in res.keypoints for k in ("steer_top", "steer_bottom", "front_axle", "crank_axle")):
        rec["faces_added_by_cuts"] = cut_fused_faces(src, res.keypoints, res.split_args)
    skipped = json.loads(scene.get(SKIPPED, "[]"))
    if skipped:
        rec["notes"] = [f"skipped {len(skipped)} hidden/collider object(s): {', '.join(skipped[:5])}"
                        + (" ..." if len(skipped) > 5 else "")] + rec.get("notes", [])
    rec["problems"] = list(res.problems)
    if source_path:
        rec["source_file"] = os.path.abspath(source_path)
    scene[RECORD] = json.dumps(rec)
    set_keypoint_empties(res.keypoints)
    try:
        split_parts(relabel=False)
    except UserError as e:
        if not res.problems:
            raise
        res.problems.append(f"split: {e} (fix the keypoints above, then Split parts)")
        rec["problems"] = list(res.problems)
        scene[RECORD] = json.dumps(rec)
    return res


def cut_fused_faces(obj, kp, split_args, rounds=3):
    """Cut the faces flagged CUT_ATTR (a fused piece lying across parts) along split.cut_planes
    (bmesh bisect: UVs and materials are interpolated onto the new faces), then label each face
    by the region at its centre, so the frame, steering and crank made from a single fused mesh
    are clean rigid pieces rather than faces labelled by their centroid.  Only faces whose
    corners lie in different regions are cut, and only by the planes that cross them.
    obj: curation_source in the canonical pose (Blender frame).  Returns the faces added."""
    import bmesh
    from ..frames import C as C_BL
    planes = [(p @ C_BL.T, n @ C_BL.T) for p, n in split.cut_planes(kp, split_args.get("head_radius"),
                                                                    split_args.get("wheel_radius"),
                                                                    split_args.get("head_span"))]

    def reg(pts_bl):
        return split.regions(to_canonical(np.asarray(pts_bl, float).reshape(-1, 3)), kp, split_args.get("head_radius"),
                             split_args.get("wheel_radius"), split_args.get("head_span"))

    bm = bmesh.new()
    bm.from_mesh(obj.data)
    n0 = len(bm.faces)
    cut_l = bm.faces.layers.int.get(CUT_ATTR)
    part_l = bm.faces.layers.int.get(PART_ATTR)
    for _ in range(rounds):
        flagged = [f for f in bm.faces if f[cut_l]]
        if not flagged:
            break
        # corners, edge midpoints and centre: a long face can cross a region with its corners outside
        corners = []
        for f in flagged:
            cs = [np.array(v.co[:]) for v in f.verts]
            corners.append(cs + [0.5 * (cs[j] + cs[j - 1]) for j in range(len(cs))] + [sum(cs) / len(cs)])
        labs = reg([c for cs in corners for c in cs])
        mixed, i = set(), 0
        for f, cs in zip(flagged, corners):
            if len(set(labs[i:i + len(cs)].tolist())) > 1:
                mixed.add(f)
            i += len(cs)
        if not mixed:
            break
        for co, no in planes:
            hit = [f for f in mixed if f.is_valid and _straddles(f, co, no)]
            if not hit:
                continue
            edges = list({e for f in hit for e in f.edges})
            verts = list({v for f in hit for v in f.verts})
            ret = bmesh.ops.bisect_plane(bm, geom=hit + edges + verts, dist=1e-6, plane_co=co.tolist(),
                                         plane_no=no.tolist())
            mixed = {f for f in mixed if f.is_valid} | {g for g in ret["geom"] if isinstance(g, bmesh.types.BMFace)}
    flagged = [f for f in bm.faces if f[cut_l]]
    if flagged:
        lab = reg([f.calc_center_median()[:] for f in flagged])
        if not split_args.get("has_crank", True):
            lab[lab == split.CRANK] = split.FRAME
        for f, k in zip(flagged, lab.tolist()):
            f[part_l] = k
    added = len(bm.faces) - n0
    bm.to_mesh(obj.data)
    bm.free()
    obj.data.update()
    return added


def _straddles(face, co, no, eps=1e-6):
    d = [(v.co[0] - co[0]) * no[0] + (v.co[1] - co[1]) * no[1] + (v.co[2] - co[2]) * no[2] for v in face.verts]
    return min(d) < -eps and max(d) > eps


def _clear_derived():
    """Remove the parts and the rig (a re-derivation makes them again)."""
    for name in PARTS + ("armature",):
        o = bpy.data.objects.get(name)
        if o is not None:
            bpy.data.objects.remove(o, do_unlink=True)


def place_wheel_empties():
    """kp.front_axle / kp.rear_axle at the two ends of the model's longest extent, half way up,
    for the annotator to drag onto the hubs (then Curate from wheel centres)."""
    src = bpy.data.objects.get(SOURCE)
    if src is None:
        src = join_meshes(bpy.context.scene)
    V, _, _ = mesh_arrays(src)
    V = V @ np.array(src.matrix_world)[:3, :3].T + np.array(src.matrix_world)[:3, 3]
    lo, hi = V.min(0), V.max(0)
    k = int(np.argmax(hi - lo))
    mid = 0.5 * (lo + hi)
    ends = []
    for t in (0.8, 0.2):
        p = mid.copy()
        p[k] = lo[k] + t * (hi[k] - lo[k])
        ends.append(p)
    scene = bpy.context.scene
    coll = bpy.data.collections.get(KP_COLLECTION) or bpy.data.collections.new(KP_COLLECTION)
    if coll.name not in scene.collection.children:
        scene.collection.children.link(coll)
    size = 0.02 * float(np.linalg.norm(hi - lo))
    for name, p in zip(("front_axle", "rear_axle"), ends):
        e = bpy.data.objects.get(f"kp.{name}")
        if e is None:
            e = bpy.data.objects.new(f"kp.{name}", None)
            coll.objects.link(e)
            e.empty_display_type = "SPHERE"
            e.show_name = True
            e.show_in_front = True
        e.empty_display_size = size
        e.location = Vector(p.tolist())
    return ends


def save_partial(path):
    """Write the scene as it is (source mesh, keypoint empties, parts so far, the record with
    its problems) to a .blend the panel resumes from; atomic (temporary file, then rename)."""
    path = os.path.abspath(os.fspath(path))
    d = os.path.dirname(path)
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(path) + ".", suffix=".blend", dir=d)
    os.close(fd)
    try:
        bpy.ops.wm.save_as_mainfile(filepath=tmp, copy=True, check_existing=False)
        os.replace(tmp, path)
    finally:
        for f in (tmp, tmp + "1"):
            if os.path.exists(f):
                os.remove(f)
    return path


def record_problems():
    """The problems stored with the curation (a partial curation opened to resume)."""
    return list(json.loads(bpy.context.scene.get(RECORD, "{}")).get("problems", []))


# ------------------------------------------------------------------ keypoint empties

def set_keypoint_empties(kp):
    scene = bpy.context.scene
    coll = bpy.data.collections.get(KP_COLLECTION)
    if coll is None:
        coll = bpy.data.collections.new(KP_COLLECTION)
    if coll.name not in scene.collection.children:
        scene.collection.children.link(coll)
    for name in KEYPOINT_NAMES:
        if name not in kp:
            continue
        oname = f"kp.{name}"
        e = bpy.data.objects.get(oname)
        if e is None:
            e = bpy.data.objects.new(oname, None)
            coll.objects.link(e)
            e.empty_display_type = "SPHERE"
            e.empty_display_size = 0.012
            e.show_name = True
            e.show_in_front = True
        e.location = Vector(to_blender(kp[name]).tolist())


def read_keypoint_empties():
    out = {}
    for name in KEYPOINT_NAMES:
        e = bpy.data.objects.get(f"kp.{name}")
        if e is not None:
            out[name] = to_canonical(np.array(e.matrix_world.translation))
    return out


def current_keypoints():
    """Keypoints from the empties, else from the armature's keypoint bones."""
    kp = read_keypoint_empties()
    if kp:
        return kp
    arm = bpy.data.objects.get("armature")
    if arm is not None:
        from ..rig.articulation import posed_keypoints
        return {k: np.asarray(v) for k, v in posed_keypoints(arm).items()}
    return {}


def snap_to_surface(objs, targets):
    """Move each empty in objs to the closest point on the target meshes' surfaces."""
    moved = 0
    for e in objs:
        best = None
        for t in targets:
            inv = t.matrix_world.inverted()
            ok, loc, nrm, idx = t.closest_point_on_mesh(inv @ e.matrix_world.translation)
            if ok:
                w = t.matrix_world @ loc
                d = (w - e.matrix_world.translation).length
                if best is None or d < best[0]:
                    best = (d, w)
        if best is not None:
            e.location = best[1]
            moved += 1
    return moved


def validate_scene():
    """Problems with the current keypoints (empties or rig); [] when they pass."""
    src = bpy.data.objects.get(SOURCE)
    has_crank = "crank" in bpy.data.objects or (src is not None and (_get_face_attr(src.data, PART_ATTR) == split.CRANK).any())
    return validate(current_keypoints(), has_crank)


# ------------------------------------------------------------------ parts

def split_parts(relabel=True):
    """(Re)create the part objects from `curation_source`: automatic labels (recomputed from
    the current keypoints when relabel), overridden by painted faces."""
    src = bpy.data.objects.get(SOURCE)
    if src is None:
        raise UserError("nothing to split: run Auto curate first")
    me = src.data
    if relabel:
        kp = read_keypoint_empties()
        V, T, tp = mesh_arrays(src)
        lab = pipeline.relabel(to_canonical(V), T, kp)
        area = np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1)
        _face_attr(me, PART_ATTR, _poly_labels(lab, tp, area, len(me.polygons)))
    lab = _get_face_attr(me, PART_ATTR, split.FRAME)
    paint = _get_face_attr(me, PAINT_ATTR)
    lab = np.where(paint >= 0, paint, lab)
    for name in PARTS:
        old = bpy.data.objects.get(name)
        if old is not None:
            bpy.data.objects.remove(old, do_unlink=True)
    out = {}
    for k, name in enumerate(PARTS):
        if not (lab == k).any():
            continue
        o = src.copy()
        o.data = me.copy()
        o.name = name
        o.data.name = name
        bpy.context.scene.collection.objects.link(o)
        _delete_faces(o, lab != k)
        for a in (PART_ATTR, PAINT_ATTR, HINT_ATTR, CUT_ATTR):
            if o.data.attributes.get(a) is not None:
                o.data.attributes.remove(o.data.attributes[a])
        o.pass_index = PASS_INDEX[name]
        o.hide_render = False
        out[name] = o
    src.hide_set(True)
    src.hide_render = True
    if "frame" not in out or "steering" not in out:
        raise UserError("the split left no " + ("frame" if "frame" not in out else "steering")
                        + " faces: check the keypoints or paint the parts")
    return out


def paint_selected(part):
    """Assign the faces selected in edit mode on curation_source to `part` (annotator repaint;
    "junk" leaves them out of every part)."""
    src = bpy.data.objects.get(SOURCE)
    if src is None:
        raise UserError("nothing to paint: run Auto curate first")
    was_edit = src.mode == "EDIT"
    if was_edit:
        bpy.ops.object.mode_set(mode="OBJECT")
    sel = np.zeros(len(src.data.polygons), bool)
    src.data.polygons.foreach_get("select", sel)
    paint = _get_face_attr(src.data, PAINT_ATTR)
    paint[sel] = JUNK_PAINT if part == "junk" else PARTS.index(part)
    _face_attr(src.data, PAINT_ATTR, paint)
    if was_edit:
        bpy.ops.object.mode_set(mode="EDIT")
    return int(sel.sum())


# ------------------------------------------------------------------ rig and save

def _spec_like(parts):
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
    arm = arm_mod.build_armature({k: list(map(float, v)) for k, v in kp.items()}, _spec_like(parts), list(parts))
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


def save(out_dir, allow_problems=False):
    """Write the bike folder (bike.blend, keypoints.json, meta.json) into out_dir, atomically:
    everything goes to a temporary sibling folder that is renamed at the end."""
    out_dir = os.path.abspath(os.fspath(out_dir))
    kp = current_keypoints()
    probs = validate(kp, "crank" in bpy.data.objects)
    if probs and not allow_problems:
        raise UserError(f"keypoints invalid: {probs[0]}" + (f" (+{len(probs) - 1} more)" if len(probs) > 1 else ""))
    arm, kp, parts = build_rig()
    # the rig is built at rest: reset any preview pose before writing
    from ..rig.articulation import apply_pose
    apply_pose(arm, 0.0, 0.0)
    remove_helpers()
    scene = bpy.context.scene
    rec = json.loads(scene.get(RECORD, "{}"))
    rec["problems"] = probs
    rec["keypoints_final"] = {k: [float(c) for c in v] for k, v in kp.items()}
    meta = {
        "bike_id": os.path.basename(out_dir), "generator": "curated", "style": "imported",
        "rideable": "bicycle", "has_crank": "crank" in parts,
        "source_file": rec.get("source_file"), "source_sha256": _sha256(rec.get("source_file")),
        "dimensions": _dimensions(kp, rec),
        "blender_version": bpy.app.version_string,
        "triangles": {n: sum(len(p.vertices) - 2 for p in o.data.polygons) for n, o in parts.items()},
        "curation": rec,
    }
    parent = os.path.dirname(out_dir)
    try:
        os.makedirs(parent, exist_ok=True)
    except OSError as e:
        raise UserError(f"cannot create {parent}: {e.strerror}") from None
    tmp = tempfile.mkdtemp(prefix="." + os.path.basename(out_dir) + ".", suffix=".tmp", dir=parent)
    try:
        bike_asset.save_bike(tmp, _spec_like(parts), {k: list(map(float, v)) for k, v in kp.items()},
                             part_keypoints(_spec_like(parts)), meta)
        if os.path.isdir(out_dir):  # replace an older curation of the same bike
            old = out_dir + ".old.tmp"
            os.rename(out_dir, old)
            os.rename(tmp, out_dir)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.rename(tmp, out_dir)
    finally:
        if os.path.isdir(tmp):
            shutil.rmtree(tmp, ignore_errors=True)
    return meta


def _sha256(path):
    if not path or not os.path.isfile(path):
        return None
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for b in iter(lambda: f.read(1 << 20), b""):
            h.update(b)
    return h.hexdigest()


def _dimensions(kp, rec):
    k = {n: np.asarray(v, float) for n, v in kp.items()}
    ax = k["steer_top"] - k["steer_bottom"]
    return {"wheel_diameter_m": rec.get("wheel_diameter_m"),
            "wheelbase_m": round(float(k["front_axle"][0] - k["rear_axle"][0]), 5),
            "head_angle_deg": round(float(np.degrees(np.arctan2(ax[1], -ax[0]))), 3),
            "bb_height_m": round(float(k["crank_axle"][1]), 5),
            "bar_width_m": round(float(k["handle_right"][2] - k["handle_left"][2]), 5)}

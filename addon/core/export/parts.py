"""Read a bike folder's part meshes out of bike.blend at the rest pose (bpy side).

The curated/generated bike.blend holds mesh objects `frame`, `steering` and `crank`,
bone-parented to `armature` (addon/core/rig/armature.py).  The armature is switched to its rest
position before the meshes are evaluated, so a pose left in the file does not leak into the export.
"""
import os

import bpy
import numpy as np

from .. import frames
from ..contract import UserError, bike_folder
from .articulation import rig_from_keypoints
from .meshes import PartMesh


def check_bike_folder(bike_dir):
    """Validate the folder's files and keypoints before Blender opens anything -> (rig, meta)."""
    if not os.path.isdir(bike_dir):
        raise UserError(f"no bike folder: {bike_dir}")
    for f in ("bike.blend", "keypoints.json", "meta.json"):
        if not os.path.isfile(os.path.join(bike_dir, f)):
            raise UserError(f"{bike_dir} has no {f} (a bike folder holds bike.blend, keypoints.json, meta.json)")
    meta = bike_folder.read_json(os.path.join(bike_dir, "meta.json"))
    if not isinstance(meta, dict):
        raise UserError(f"{bike_dir}/meta.json is not a JSON object")
    has_crank = meta.get("has_crank", True)
    if not isinstance(has_crank, bool):
        raise UserError(f"{bike_dir}/meta.json has_crank must be true or false, got {has_crank!r}")
    rig = rig_from_keypoints(bike_folder.read_json(os.path.join(bike_dir, "keypoints.json")), has_crank,
                             os.path.join(bike_dir, "keypoints.json"))
    return rig, meta


def _material(mat):
    if mat is None:
        return ("default", (0.8, 0.8, 0.8, 1.0), 0.0, 0.6)
    tree = getattr(mat, "node_tree", None)
    bsdf = next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None) if tree else None
    if bsdf is not None:
        rgba = tuple(float(x) for x in bsdf.inputs["Base Color"].default_value)
        return (mat.name, rgba, float(bsdf.inputs["Metallic"].default_value),
                float(bsdf.inputs["Roughness"].default_value))
    return (mat.name, tuple(float(x) for x in mat.diffuse_color), float(mat.metallic), float(mat.roughness))


def load_part_meshes(bike_dir, parts):
    """Open bike.blend (replacing the current file) -> {part: PartMesh} in the canonical frame."""
    path = os.path.join(bike_dir, "bike.blend")
    try:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(path))
    except RuntimeError as e:
        raise UserError(f"Blender cannot open {path}: {str(e).strip().splitlines()[-1]}")
    missing = [p for p in parts if p not in bpy.data.objects or bpy.data.objects[p].type != "MESH"]
    if missing:
        raise UserError(f"{path} has no mesh object(s) {', '.join(missing)}")
    for arm in (o for o in bpy.data.objects if o.type == "ARMATURE"):
        arm.data.pose_position = "REST"
    bpy.context.view_layer.update()
    dg = bpy.context.evaluated_depsgraph_get()
    out = {}
    for p in parts:
        obj = bpy.data.objects[p].evaluated_get(dg)
        me = obj.to_mesh()
        try:
            me.calc_loop_triangles()
            v = np.empty(len(me.vertices) * 3)
            me.vertices.foreach_get("co", v)
            t = np.empty(len(me.loop_triangles) * 3, np.int64)
            me.loop_triangles.foreach_get("vertices", t)
            mi = np.empty(len(me.loop_triangles), np.int64)
            me.loop_triangles.foreach_get("material_index", mi)
        finally:
            obj.to_mesh_clear()
        M = np.array(obj.matrix_world)
        world = v.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
        mats = [_material(s.material) for s in obj.material_slots]
        if len(t) == 0:
            raise UserError(f"{path}: part {p} has no faces")
        mi = np.clip(mi, 0, max(len(mats) - 1, 0))
        out[p] = PartMesh(p, frames.to_canonical(world), t.reshape(-1, 3), mi, mats)
    return out


def convex_hull(points):
    """(k, 3) points -> (verts, tris) of their convex hull (bmesh; closes an open shell)."""
    import bmesh

    bm = bmesh.new()
    try:
        for p in points:
            bm.verts.new(p)
        res = bmesh.ops.convex_hull(bm, input=bm.verts, use_existing_faces=False)
        for g in ("geom_interior", "geom_unused"):
            bmesh.ops.delete(bm, geom=[e for e in res[g] if isinstance(e, bmesh.types.BMVert)], context="VERTS")
        bmesh.ops.triangulate(bm, faces=bm.faces[:])
        bm.verts.index_update()
        verts = np.array([v.co[:] for v in bm.verts])
        tris = np.array([[v.index for v in f.verts] for f in bm.faces], np.int64)
    finally:
        bm.free()
    return verts, tris

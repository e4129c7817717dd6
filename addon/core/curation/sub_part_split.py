"""Give a saved bike folder its wheel and pedal sub-parts (docs/contract.md "Sub-parts"): the
faces sub_parts.py finds on frame / steering / crank become their own mesh objects (their
main part's pass_index), the armature is rebuilt with the wheel bones and level pedal bones, and
bike.blend + meta.json ("sub_parts", "gear_ratio", "triangles") are written again.

Curated bikes come out of curation split into the three parts only; curate.py runs this after
saving (unless --no-sub-parts), and blender_scripts/add_sub_parts.py runs it on any bike folder.
Views and Gaussians rendered or trained before it describe the old parts: render and train again.
"""
import os

import bpy
import numpy as np

from ..rig import armature as arm_mod
from ..rig.articulation import apply_pose
from ..bike_asset import open_bike, save_bike
from ..contract import UserError, bike_folder, instances
from .scene_state import delete_faces
from .sub_parts import SOURCES, sub_part_triangles
from ..frames import to_canonical

DEFAULT_GEAR_RATIO = 2.6  # a 44/17 city or trekking gear, for a model that does not say its own


def _canonical_triangles(obj):
    """(V canonical (n, 3), T (m, 3) vertex indices, polygon index per triangle) of a mesh object."""
    me = obj.data
    me.calc_loop_triangles()
    V = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", V)
    mw = np.array(obj.matrix_world)
    V = to_canonical(V.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3])
    T = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("vertices", T)
    P = np.empty(len(me.loop_triangles), np.int64)
    me.loop_triangles.foreach_get("polygon_index", P)
    return V, T.reshape(-1, 3), P


def split_sub_parts(parts, kp):
    """Cut the sub-parts out of the part objects in place: {name: object} for the new ones."""
    found = {}
    for main in ("frame", "steering", "crank"):
        obj = parts.get(main)
        if obj is None:
            continue
        V, T, P = _canonical_triangles(obj)
        sel = sub_part_triangles(main, V, T, kp)
        n_poly = len(obj.data.polygons)
        masks = {}
        for sub, tri in sel.items():
            m = np.zeros(n_poly, bool)
            m[P[tri]] = True
            masks[sub] = m
        for sub, m in masks.items():
            o = obj.copy()
            o.data = obj.data.copy()
            o.name = o.data.name = sub
            for c in obj.users_collection:
                c.objects.link(o)
            delete_faces(o, ~m)
            o.pass_index = instances.SUB_PART_IDS[sub]
            found[sub] = o
        if masks:
            delete_faces(obj, np.any(list(masks.values()), axis=0))
    return found


def add_sub_parts(bike_dir, gear_ratio=None, progress=print):
    """Open bike_dir, split off its sub-parts, rebuild the rig, save.  Returns the new meta.json.
    gear_ratio: wheel turns per crank turn (default: meta.json's, else DEFAULT_GEAR_RATIO)."""
    bike = open_bike(bike_dir)
    meta = dict(bike["meta"])
    if meta.get("sub_parts"):
        raise UserError(f"{bike_dir}: already has sub-parts {', '.join(meta['sub_parts'])}")
    if gear_ratio is not None and not (np.isfinite(gear_ratio) and 0.5 <= gear_ratio <= 8.0):
        raise UserError(f"--gear-ratio must be within 0.5..8, got {gear_ratio}")
    arm = bike["armature"]
    apply_pose(arm, 0.0, 0.0)  # the rest pose: the rig is rebuilt from it
    kp = {k: np.asarray(v, float) for k, v in bike["keypoints"].items()}
    parts = {k: o for k, o in bike["parts"].items() if k in bike_folder.PARTS}
    for o in parts.values():  # unparent, keeping the rest placement
        mw = o.matrix_world.copy()
        o.parent = None
        o.matrix_world = mw
    bpy.data.objects.remove(arm, do_unlink=True)
    found = split_sub_parts(parts, kp)
    parts.update(found)
    has_crank = "crank" in parts
    g = None
    if has_crank and any(s.endswith("_wheel") for s in found):
        g = float(gear_ratio if gear_ratio is not None else meta.get("gear_ratio", DEFAULT_GEAR_RATIO))
    spec = {"rideable": "bicycle" if has_crank else "no_crank"}
    arm = arm_mod.build_armature({k: v.tolist() for k, v in kp.items()}, spec, list(parts), gear_ratio=g)
    for name, o in parts.items():
        arm_mod.attach(o, arm, name)
    bpy.context.view_layer.update()
    meta["sub_parts"] = [s for s in bike_folder.SUB_PARTS if s in found]
    if g is not None:
        meta["gear_ratio"] = round(g, 5)
    meta["triangles"] = {n: sum(len(p.vertices) - 2 for p in o.data.polygons) for n, o in parts.items()}
    kp_doc = bike_folder.read_json(os.path.join(bike_dir, "keypoints.json"))
    save_bike(bike_dir, spec, kp_doc["keypoints"], kp_doc.get("parts"), meta)
    missing = [s for s in SOURCES if s not in found and (has_crank or not s.startswith("pedal"))]
    progress(f"{os.path.basename(os.path.normpath(bike_dir))}: sub-parts {', '.join(meta['sub_parts']) or 'none'}"
             + (f" (not found as separate pieces: {', '.join(missing)})" if missing else "")
             + "; render the views and train the parts again")
    return meta

"""The annotator's working state lives in the scene (the bpy side of curation):

- `curation_source`: the imported model joined into one mesh, in the canonical pose (Blender
  frame) after auto_curate; face attributes `articcyc_part` (automatic label) and
  `articcyc_paint` (annotator override, -1 = none).
- collection `keypoints`: one labelled empty `kp.<name>` per keypoint (drag/snap them).
- `frame`, `steering`, `crank`: the split parts (pass_index 1/2/3), `armature`: the rig.
- scene["articcyc_curation"]: the curation record (JSON) that goes into meta.json.

This module holds those names and the face-attribute helpers the other curation steps share.
"""
import json

import bmesh
import bpy
import numpy as np

from . import split


SOURCE = "curation_source"
KP_COLLECTION = "keypoints"
PART_ATTR, PAINT_ATTR, HINT_ATTR = "articcyc_part", "articcyc_paint", "articcyc_hint"
CUT_ATTR = "articcyc_cut"   # faces of a fused piece: cut along the part boundaries, labelled per piece
RECORD = "articcyc_curation"
SKIPPED = "articcyc_skipped_objects"
JUNK_PAINT = 9   # painted "not the bike": left out of every part
PARTS = ("frame", "steering", "crank")


def face_attr(mesh, name, values=None):
    a = mesh.attributes.get(name)
    if a is None:
        a = mesh.attributes.new(name, "INT", "FACE")
    if values is not None:
        a.data.foreach_set("value", np.asarray(values, np.int32))
    return a


def get_face_attr(mesh, name, default=-1):
    a = mesh.attributes.get(name)
    out = np.full(len(mesh.polygons), default, np.int32)
    if a is not None and a.domain == "FACE":
        a.data.foreach_get("value", out)
    return out


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


def poly_labels(tri_labels, tri_poly, tri_area, n_poly):
    """One label per polygon: the label of most of its area."""
    out = np.full(n_poly, split.JUNK, np.int32)
    best = np.full(n_poly, -1.0)
    for lab in (split.JUNK, split.FRAME, split.STEERING, split.CRANK):
        w = np.bincount(tri_poly, weights=tri_area * (tri_labels == lab), minlength=n_poly)
        better = w > best
        out[better], best[better] = lab, w[better]
    return out


def delete_faces(obj, mask):
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bm.faces.ensure_lookup_table()
    bmesh.ops.delete(bm, geom=[f for f in bm.faces if mask[f.index]], context="FACES")
    loose = [v for v in bm.verts if not v.link_faces]
    bmesh.ops.delete(bm, geom=loose, context="VERTS")
    bm.to_mesh(obj.data)
    bm.free()
    obj.data.update()


def record_problems():
    """The problems stored with the curation (a partial curation opened to resume)."""
    return list(json.loads(bpy.context.scene.get(RECORD, "{}")).get("problems", []))

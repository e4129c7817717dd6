"""The part objects `frame`, `steering`, `crank` split from `curation_source` by the automatic labels
and the faces the annotator painted."""
import bpy
import numpy as np

from ..contract import UserError
from ..frames import to_canonical
from ..procedural.build import PASS_INDEX
from . import pipeline, split
from .keypoint_empties import read_keypoint_empties
from .scene_state import (CUT_ATTR, HINT_ATTR, JUNK_PAINT, PAINT_ATTR, PART_ATTR, PARTS, SOURCE, delete_faces,
                          face_attr, get_face_attr, mesh_arrays, poly_labels)


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
        face_attr(me, PART_ATTR, poly_labels(lab, tp, area, len(me.polygons)))
    lab = get_face_attr(me, PART_ATTR, split.FRAME)
    paint = get_face_attr(me, PAINT_ATTR)
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
        delete_faces(o, lab != k)
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
    paint = get_face_attr(src.data, PAINT_ATTR)
    paint[sel] = JUNK_PAINT if part == "junk" else PARTS.index(part)
    face_attr(src.data, PAINT_ATTR, paint)
    if was_edit:
        bpy.ops.object.mode_set(mode="EDIT")
    return int(sel.sum())

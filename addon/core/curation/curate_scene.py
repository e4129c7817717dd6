"""Auto curate the scene's model: join, pose, scale, label, cut, place the keypoint empties and split
the parts (pipeline.curate_arrays does the numpy work)."""
import json
import os

import bpy
import numpy as np
from mathutils import Matrix

from ..contract import UserError
from ..frames import C
from . import pipeline, split
from .face_cuts import cut_fused_faces
from .join_source import join_meshes
from .keypoint_empties import set_keypoint_empties
from .part_objects import split_parts
from .scene_state import (CUT_ATTR, HINT_ATTR, PAINT_ATTR, PART_ATTR, PARTS, RECORD, SKIPPED, SOURCE, delete_faces,
                          face_attr, get_face_attr, mesh_arrays, poly_labels)


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
    hints_poly = get_face_attr(src.data, HINT_ATTR)
    paint_before = get_face_attr(src.data, PAINT_ATTR) if again else None
    res = pipeline.curate_arrays(V, T, wheel_diameter, keypoints,
                                 hints=hints_poly[tp] if (hints_poly >= 0).any() else None,
                                 wheel_centres=wheel_centres)
    area = np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1)
    plab = poly_labels(res.labels, tp, area, len(src.data.polygons))
    c4 = np.eye(4)
    c4[:3, :3] = C
    src.data.transform(Matrix((c4 @ res.M).tolist()))
    face_attr(src.data, PART_ATTR, plab)
    paint = np.where(hints_poly >= 0, hints_poly, -1)
    if paint_before is not None:
        paint = np.where(paint_before >= 0, paint_before, paint)
    face_attr(src.data, PAINT_ATTR, paint)
    cut_poly = (np.bincount(tp, weights=res.cut.astype(float), minlength=len(plab)) > 0) & (paint < 0)
    face_attr(src.data, CUT_ATTR, cut_poly.astype(np.int32))
    delete_faces(src, (plab == split.JUNK) & (paint < 0))
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


def _clear_derived():
    """Remove the parts and the rig (a re-derivation makes them again)."""
    for name in PARTS + ("armature",):
        o = bpy.data.objects.get(name)
        if o is not None:
            bpy.data.objects.remove(o, do_unlink=True)

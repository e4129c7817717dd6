"""Save a curation: the finished bike folder (bike.blend, keypoints.json, meta.json), or a partial
.blend the annotator panel resumes from; both atomic."""
import hashlib
import json
import os
import shutil
import tempfile

import bpy
import numpy as np

from .. import bike_asset
from ..contract import UserError
from ..procedural.layout import part_keypoints
from ..rig.articulation import apply_pose
from .keypoint_empties import current_keypoints
from .rigging import build_rig, remove_helpers, spec_like
from .scene_state import RECORD
from .validate import validate


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
        bike_asset.save_bike(tmp, spec_like(parts), {k: list(map(float, v)) for k, v in kp.items()},
                             part_keypoints(spec_like(parts)), meta)
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

"""The keypoints as labelled empties `kp.<name>` the annotator drags: read from a JSON file, placed,
read back (or from the rig), snapped to the surface, validated."""
import json

import bpy
import numpy as np
from mathutils import Vector

from ..contract import UserError
from ..frames import to_blender, to_canonical
from ..procedural.layout import KEYPOINT_NAMES
from ..rig.articulation import posed_keypoints
from . import split
from .join_source import join_meshes
from .scene_state import KP_COLLECTION, PART_ATTR, SOURCE, get_face_attr, mesh_arrays
from .validate import validate


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
    # matrix_world follows location only after a view-layer update (Blender runs one between two
    # operators): without it a script's next read_keypoint_empties() would see the empties at the origin
    bpy.context.view_layer.update()


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
    has_crank = "crank" in bpy.data.objects or (src is not None and (get_face_attr(src.data, PART_ATTR) == split.CRANK).any())
    return validate(current_keypoints(), has_crank)

"""Join the imported model into one mesh, `curation_source`: hidden objects and collision proxies
left out, part hints from object or vertex-group names kept as a face attribute."""
import json

import bpy
import numpy as np

from ..contract import UserError
from .scene_state import HINT_ATTR, PARTS, SKIPPED, SOURCE, face_attr


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
        face_attr(me, HINT_ATTR, _hint_for(o, use_names) if len(o.data.polygons) == len(me.polygons)
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

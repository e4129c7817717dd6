"""Scene-level helpers (bpy): reset, version switches."""
import bpy

BLENDER_VERSION = bpy.app.version  # (3, 4, 1) for Debian's binary, (5, 0, 1) for the pip module


def reset_scene():
    """An empty scene, as if Blender had just started with no startup file."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def link(obj, collection=None):
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def world_mesh_arrays(obj, depsgraph=None):
    """An object's evaluated mesh in world space (Blender frame): vertices (V, 3), triangles (T, 3)."""

    import numpy as np

    dg = depsgraph or bpy.context.evaluated_depsgraph_get()
    me = bpy.data.meshes.new_from_object(obj.evaluated_get(dg))
    me.transform(obj.matrix_world)
    me.calc_loop_triangles()
    V = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", V)
    T = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("vertices", T)
    bpy.data.meshes.remove(me)
    return V.reshape(-1, 3), T.reshape(-1, 3)

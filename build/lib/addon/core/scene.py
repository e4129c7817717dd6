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

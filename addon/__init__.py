"""3DArticCyclists Blender side.

`addon.core` holds the bpy-side core (procedural bikes, curation, articulation, rendering) that
the headless scripts in blender_scripts/ call.  As an add-on (Blender 4.2+ extension via
blender_manifest.toml, or a legacy add-on in 3.x via bl_info) it adds the annotator panel:
View3D > Sidebar > ArticCyclists.  bpy is imported only in register(), so `addon.core.frames`
and the numpy-only modules stay importable without Blender.
"""

bl_info = {
    "name": "3DArticCyclists",
    "author": "3DArticCyclists contributors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > ArticCyclists",
    "description": "Curate imported bicycle models: canonical pose, keypoints, parts, rig, 36-view renders",
    "category": "3D View",
}


def register():
    from . import operators, panel
    operators.register()
    panel.register()


def unregister():
    from . import operators, panel
    panel.unregister()
    operators.unregister()

"""3DArticCyclists Blender side.

`addon.core` holds the bpy-side core (procedural bikes, curation, articulation, rendering) that
the headless scripts in blender_scripts/ call.  As an add-on (Blender 4.2+ extension via
blender_manifest.toml, or a legacy add-on in 3.x via bl_info) it adds the annotator panel:
View3D > Sidebar > ArticCyclists.  bpy is imported only in register(), so `addon.core.frames`
and the numpy-only modules stay importable without Blender.

Everything the add-on does needs numpy.  Blender's own builds bundle it, but a distribution's
Blender uses the system Python (Debian's `blender` neither depends on nor recommends
python3-numpy), so register() checks once: without numpy the sidebar shows what to install
and every operator refuses with the same words instead of a ModuleNotFoundError.
"""
from .requirements import _MISSING, missing_numpy_message, requirements_problem  # noqa: F401  (the add-on's API)

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
    _MISSING[:] = [m for m in (missing_numpy_message(),) if m]
    from . import operators, panel
    operators.register()
    panel.register()


def unregister():
    from . import operators, panel
    panel.unregister()
    operators.unregister()

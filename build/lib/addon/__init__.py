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
import sys

bl_info = {
    "name": "3DArticCyclists",
    "author": "3DArticCyclists contributors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > ArticCyclists",
    "description": "Curate imported bicycle models: canonical pose, keypoints, parts, rig, 36-view renders",
    "category": "3D View",
}


_MISSING = []  # register() stores the missing-numpy message here, or nothing


def missing_numpy_message():
    """None when numpy imports; else one line naming the package and how to install it."""
    try:
        import numpy  # noqa: F401
    except ImportError as e:  # absent, or built for another Python (a broken system copy)
        why = "is not installed" if getattr(e, "name", None) == "numpy" else f"fails to import ({e})"
        return (f"3DArticCyclists needs the Python package numpy, which {why} in this Blender's Python: "
                f"install it (Debian/Ubuntu: sudo apt install python3-numpy; other Blenders: "
                f"{sys.executable} -m pip install numpy) and restart Blender")
    return None


def requirements_problem():
    """The message the panel shows and the operators refuse with, or None (checked at register)."""
    return _MISSING[0] if _MISSING else None


def register():
    _MISSING[:] = [m for m in (missing_numpy_message(),) if m]
    from . import operators, panel
    operators.register()
    panel.register()


def unregister():
    from . import operators, panel
    panel.unregister()
    operators.unregister()

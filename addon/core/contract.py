"""The file contract (the `cyclist_formats` package) as the Blender side imports it.

In the repository and in a pip-installed project `cyclist_formats` is a top-level package (the
blender_scripts put the repository on sys.path).  Inside the add-on zip, blender_scripts/
build_addon.py copies it into the add-on's own folder, because an installed extension sees only
its folder; the relative import finds that copy.

Only the numpy-free modules load here; the others (ring, pose, ply, bike_folder, ...) load on
first use, so the add-on registers, and tells the user what to install, in a Blender without
numpy (tests/test_addon_manifest.py).
"""
import importlib

try:
    from ..cyclist_formats import atomic, errors  # inside the add-on zip
    _PACKAGE = __package__.rsplit(".", 1)[0] + ".cyclist_formats"
except ImportError:
    from cyclist_formats import atomic, errors
    _PACKAGE = "cyclist_formats"

UserError = errors.UserError
atomic_path, temp_name, write_json, write_bytes = atomic.atomic_path, atomic.temp_name, atomic.write_json, atomic.write_bytes


def __getattr__(name):
    """`from .contract import ring` etc.: the module, imported now."""
    try:
        return importlib.import_module(f"{_PACKAGE}.{name}")
    except ModuleNotFoundError as e:
        if e.name == f"{_PACKAGE}.{name}":
            raise AttributeError(f"cyclist_formats has no module {name!r}") from None
        raise

"""The file contract (the numpy-only `cyclist_formats` package) as the Blender side imports it.

In the repository and in a pip-installed project `cyclist_formats` is a top-level package (the
blender_scripts put the repository on sys.path).  Inside the add-on zip, blender_scripts/
build_addon.py copies it into the add-on's own folder, because an installed extension sees only
its folder; the relative import finds that copy.
"""
try:
    from ..cyclist_formats import atomic, bike_folder, errors, instances, ply, pose, ring  # add-on zip
except ImportError:
    from cyclist_formats import atomic, bike_folder, errors, instances, ply, pose, ring  # noqa: F401

UserError = errors.UserError
atomic_path, temp_name, write_json, write_bytes = atomic.atomic_path, atomic.temp_name, atomic.write_json, atomic.write_bytes

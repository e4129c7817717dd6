"""Import a model file into the current scene (bpy), across Blender 3.4 and 5.0.

Operator names changed between versions (OBJ: wm.obj_import since 3.2, import_scene.obj until
3.x; PLY: wm.ply_import since 3.6, import_mesh.ply before; STL: wm.stl_import since 4.1,
import_mesh.stl before), so each format lists the operators to try in order.  A .blend is
appended: the objects of its main scene (named "Scene", else the first) are linked into the current scene (other scenes hold
alternatives, studio sets, not the bike).  glTF files with Draco-compressed meshes go through the
same importer (it carries the Draco decoder).
"""
import contextlib
import os
import re
import sys
import tempfile

import bpy

from ..contract import UserError

FORMATS = {
    ".glb": [("import_scene", "gltf")], ".gltf": [("import_scene", "gltf")],
    ".obj": [("wm", "obj_import"), ("import_scene", "obj")],
    ".fbx": [("import_scene", "fbx")],
    ".ply": [("wm", "ply_import"), ("import_mesh", "ply")],
    ".stl": [("wm", "stl_import"), ("import_mesh", "stl")],
}
EXTENSIONS = tuple(sorted(list(FORMATS) + [".blend"]))


def _operator(ext):
    for mod, name in FORMATS[ext]:
        op = getattr(getattr(bpy.ops, mod), name)
        try:
            op.get_rna_type()
            return op
        except (AttributeError, KeyError):
            continue
    raise UserError(f"this Blender ({bpy.app.version_string}) has no importer for {ext} files")


def import_model(path):
    """Import `path`; returns the list of new objects.  UserError for a missing, unsupported or
    unreadable file, or one that adds nothing."""
    path = os.path.abspath(os.fspath(path))
    if not os.path.isfile(path):
        raise UserError(f"model file not found: {path}")
    ext = os.path.splitext(path)[1].lower()
    if ext not in EXTENSIONS:
        raise UserError(f"unsupported model format '{ext}' (supported: {', '.join(EXTENSIONS)})")
    if os.path.getsize(path) == 0:
        raise UserError(f"{path}: empty file")
    before = set(bpy.data.objects)
    if ext == ".blend":
        _append_blend(path)
    else:
        if ext in (".glb", ".gltf"):
            _numpy_bool_alias()
        if ext == ".fbx":
            _fbx_light_shadow_property()
        op = _operator(ext)
        try:
            with _stderr_kept_on_success():
                res = op(filepath=path)
        except Exception as e:  # importers raise RuntimeError or their own errors on bad files
            lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
            # the exception's own line in a wrapped traceback says why; else the last line
            why = [ln for ln in lines if re.match(r"^[A-Za-z_.]*(Error|Exception)\b[^:]*:", ln)
                   and not ln.startswith("Error: Python")]
            msg = (why[-1] if why else lines[-1] if lines else type(e).__name__)[:300]
            made = [o for o in bpy.data.objects if o not in before]
            where = ""
            if made:  # the importer builds objects in file order: it broke on the one after these
                where = f"; it broke after {len(made)} object(s), the last one read was '{made[-1].name}' ({made[-1].type})"
            raise UserError(f"{path}: cannot import ({msg}){where}") from None
        if "FINISHED" not in res:
            raise UserError(f"{path}: the importer gave up ({', '.join(res)})")
    new = [o for o in bpy.data.objects if o not in before]
    if not new:
        raise UserError(f"{path}: the file holds no objects (empty scene)")
    return new


def _numpy_bool_alias():
    """Blender 3.4's glTF importer calls numpy.bool, an alias of the builtin bool that numpy 1.24
    removed (and 2.0 brought back as numpy.bool_); Debian's Blender 3.4 runs on the system numpy
    1.24, where every glTF import stopped with "module 'numpy' has no attribute 'bool'".  Put the
    old alias back for that importer; newer numpy and Blender are left as they are."""
    import numpy as np
    if not hasattr(np, "bool"):
        np.bool = bool


def _fbx_light_shadow_property():
    """Blender 5.0's FBX importer sets `light.cycles.cast_shadow` on every lamp it reads, a
    property Cycles no longer has: any FBX with a lamp stopped with "'CyclesLightSettings' object
    has no attribute 'cast_shadow'".  Give Cycles' light settings that (unused) property back so
    the import runs to the end; the lamps are dropped with the other non-mesh objects anyway.
    Blender versions whose Cycles still has it are left as they are."""
    light = bpy.data.lights.new("articcyc_probe", "POINT")
    try:
        settings = getattr(light, "cycles", None)
        if settings is not None and not hasattr(settings, "cast_shadow"):
            type(settings).cast_shadow = bpy.props.BoolProperty(default=True)
    finally:
        bpy.data.lights.remove(light)


@contextlib.contextmanager
def _stderr_kept_on_success():
    """Blender prints an importer's Python traceback on stderr itself before the operator raises;
    the user should see one line saying why (import_model's UserError), not the traceback.  So
    the importer's stderr (file descriptor 2: Blender writes it from C) goes to a temporary file
    and is passed on only when the import succeeds (its warnings)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        ok = False
        try:
            yield
            ok = True
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            if ok:
                tmp.seek(0)
                text = tmp.read()
                if text:
                    os.write(2, text)


def _append_blend(path):
    try:
        with bpy.data.libraries.load(path, link=False) as (src, dst):
            # the main scene: Blender's default name when present (a library lists scenes
            # by name, not in the order the author made them), else the first
            main = [n for n in src.scenes if n == "Scene"] or list(src.scenes[:1])
            dst.scenes = main
            if not src.scenes:
                dst.objects = list(src.objects)
    except (OSError, RuntimeError) as e:
        msg = " ".join(str(e).split())[:300]
        raise UserError(f"{path}: cannot read .blend ({msg})") from None
    coll = bpy.context.scene.collection
    if dst.scenes and dst.scenes[0] is not None:
        sc = dst.scenes[0]
        objs = [o for o in sc.objects]
        for o in objs:
            if o.name not in coll.objects:
                coll.objects.link(o)
        bpy.data.scenes.remove(sc)
        return
    for o in dst.objects:
        if o is not None and o.name not in coll.objects:
            coll.objects.link(o)

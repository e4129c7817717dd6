"""A bike asset folder on disk: bike.blend + keypoints.json + meta.json (docs/contract.md layout).

save_bike writes each file under a temporary name and renames it, meta.json last, so a folder
holding all three files is complete (make_bikes skips those on a rerun).
"""
import os

import bpy

from .contract import UserError, atomic_path, bike_folder, write_json

FILES = bike_folder.FILES


def is_complete(bike_dir):
    return all(os.path.isfile(os.path.join(bike_dir, f)) for f in FILES)


def save_bike(out_dir, spec, keypoints, parts, meta):
    """Write the current scene as out_dir/bike.blend, then keypoints.json, then meta.json.

    parts: {part: [keypoint names it carries]}; meta: the dict written to meta.json.
    """
    os.makedirs(out_dir, exist_ok=True)
    with atomic_path(os.path.join(out_dir, "bike.blend")) as tmp:
        os.remove(tmp)  # an existing file would make Blender write a .blend1 backup beside it
        try:
            bpy.ops.wm.save_as_mainfile(filepath=tmp, copy=True, check_existing=False, compress=True)
        finally:
            if os.path.exists(tmp + "1"):
                os.remove(tmp + "1")
    write_json(os.path.join(out_dir, "keypoints.json"), bike_folder.keypoints_doc(keypoints, parts))
    write_json(os.path.join(out_dir, "meta.json"), meta)


def blend_file_version(path):
    """(major, minor) of the Blender that wrote `path`, from its header; None if unknown.

    Blender 5.0 writes zstd-compressed files whose first block keeps the header as literal
    bytes, so the header is searched for in the first bytes rather than read at offset 0.
    """
    with open(path, "rb") as f:
        head = f.read(96)
    i = head.find(b"BLENDER")
    if i < 0:
        return None  # let Blender decide (and report)
    h = head[i:]
    try:
        if h[7:8] in (b"-", b"_"):               # classic header: BLENDER-v304
            v = int(h[9:12])
        else:                                    # 5.x large header: BLENDER17-01v0500
            j = h.index(b"v", 7)
            v = int(h[j + 1:j + 5])
    except ValueError:
        return None
    return divmod(v, 100)


def _read_json(path):
    return bike_folder.read_json(path, missing=f"{path}: missing (not a bike folder written by make_bikes/curate?)")


def open_bike(bike_dir):
    """Open bike_dir/bike.blend. Returns dict(parts={name: obj}, armature=obj, keypoints, meta).

    Raises UserError (one line) for a missing folder/file, an unreadable or too-new .blend,
    or a .blend without the expected objects.
    """
    bike_dir = os.fspath(bike_dir)
    if not os.path.isdir(bike_dir):
        raise UserError(f"bike folder not found: {bike_dir}")
    blend = os.path.join(bike_dir, "bike.blend")
    if not os.path.isfile(blend):
        raise UserError(f"{blend}: missing")
    ver = blend_file_version(blend)
    if ver is not None and ver > tuple(bpy.app.version[:2]):
        raise UserError(f"{blend}: written by Blender {ver[0]}.{ver[1]}, cannot be opened by "
                        f"Blender {bpy.app.version_string}; regenerate it with this Blender")
    try:
        bpy.ops.wm.open_mainfile(filepath=blend)
    except RuntimeError as e:
        msg = " ".join(str(e).split())
        raise UserError(f"{blend}: cannot open ({msg})") from None
    kp_doc = _read_json(os.path.join(bike_dir, "keypoints.json"))
    meta = _read_json(os.path.join(bike_dir, "meta.json"))
    objs = bpy.data.objects
    parts = {n: objs[n] for n in bike_folder.PARTS + bike_folder.SUB_PARTS if n in objs and objs[n].type == "MESH"}
    arm = objs.get("armature")
    if "frame" not in parts or "steering" not in parts or arm is None or arm.type != "ARMATURE":
        raise UserError(f"{blend}: expected mesh objects 'frame', 'steering' and an 'armature'")
    return {"parts": parts, "armature": arm, "keypoints": kp_doc.get("keypoints", {}), "meta": meta}

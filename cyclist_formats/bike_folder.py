"""A bike's folder (docs/contract.md "Bike folder"), the same whether make_bikes or curate wrote it:

    <bike>/bike.blend  keypoints.json  meta.json
    <bike>/views/<part>/cameras.json  transforms.json  keypoints.json  points.ply
    <bike>/views/<part>/rgba/cameraNNNN/0000.png   straight alpha (what training reads)
    <bike>/views/<part>/img/cameraNNNN/0000.jpg    RGB composited on black (SHERF)
    <bike>/views/<part>/mask/cameraNNNN/0000.png   alpha > 0.5 -> 255
    <bike>/views/<part>/albedo|normal/cameraNNNN/0000.png   the render's passes (PASSES below)
    <bike>/gaussians/<part>.ply + <part>.json      trained part Gaussians and their metrics
    <bike>/gaussians/<part>.relight.npz            optional per-Gaussian albedo + normal (relight_path)
"""
import json
import os

import numpy as np

from .atomic import atomic_path, write_json
from . import text_files
from .errors import UserError

FILES = ("bike.blend", "keypoints.json", "meta.json")
PARTS = ("frame", "steering", "crank")
# optional sub-parts (docs/contract.md "Sub-parts"): cut out of the part named here, moving with it
# plus their own motion (wheels spin about their axle, pedals stay level); meta.json "sub_parts"
# lists the ones a bike has, "gear_ratio" couples the wheels to theta_p
SUB_PARTS = ("front_wheel", "rear_wheel", "pedal_left", "pedal_right")
SUB_PART_OF = {"front_wheel": "steering", "rear_wheel": "frame", "pedal_left": "crank", "pedal_right": "crank"}
KEYPOINTS = ("seat", "steer_top", "steer_bottom", "handle_left", "handle_right", "crank_axle",
             "pedal_left", "pedal_right", "front_axle", "rear_axle", "ground")
CRANK_KEYPOINTS = ("crank_axle", "pedal_left", "pedal_right")
# keypoints that keypoints.json "parts" does not list belong to these parts (else to frame)
DEFAULT_KEYPOINT_PARTS = {"steering": ("handle_left", "handle_right", "front_axle"),
                          "crank": ("pedal_left", "pedal_right")}
WHOLE = "whole"
FRAME = "0000"  # the single time step of a static part
MASK_ALPHA = 127  # 8-bit alpha above this (alpha > 0.5) is inside the mask


def read_json(path, what="JSON file", missing=None):
    """Load a JSON file; every failure is one UserError naming the file (`missing`: the message
    for a file that does not exist)."""
    return text_files.read_json(path, what, missing)


def check_bike_dir(bike_dir):
    bike_dir = os.fspath(bike_dir)
    if not os.path.isdir(bike_dir):
        raise UserError(f"bike folder not found: {bike_dir}")
    return bike_dir


def read_meta(bike_dir):
    meta = read_json(os.path.join(check_bike_dir(bike_dir), "meta.json"),
                     "bike meta.json written by make_bikes/curate")
    if not isinstance(meta, dict):
        raise UserError(f"{os.path.join(bike_dir, 'meta.json')}: expected an object")
    return meta


def read_keypoints(bike_dir_or_file):
    """keypoints.json (a bike folder's or a views folder's) -> {name: (3,) float64}, canonical metres."""
    p = os.fspath(bike_dir_or_file)
    path = os.path.join(p, "keypoints.json") if os.path.isdir(p) else p
    doc = read_json(path, "keypoints.json")
    kp = doc.get("keypoints") if isinstance(doc, dict) else None
    if not isinstance(kp, dict):
        raise UserError(f"{path}: expected {{\"keypoints\": {{name: [x, y, z]}}}}")
    out = {}
    for k, v in kp.items():
        try:
            a = np.asarray(v, dtype=np.float64).reshape(3)
        except (TypeError, ValueError):
            raise UserError(f"{path}: keypoint '{k}' is not 3 numbers") from None
        if not np.isfinite(a).all():
            raise UserError(f"{path}: keypoint '{k}' is not finite")
        out[k] = a
    return out


def sub_parts(meta):
    """The sub-parts a bike's meta.json lists (SUB_PARTS order); UserError for an unknown name
    or wheels without a positive gear_ratio."""
    names = meta.get("sub_parts", [])
    if not isinstance(names, list) or any(n not in SUB_PARTS for n in names):
        raise UserError(f"meta.json sub_parts must be a list of {', '.join(SUB_PARTS)}, got {names!r}")
    if any(n.endswith("_wheel") for n in names) and meta.get("has_crank", True):
        g = meta.get("gear_ratio")
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not np.isfinite(g) or g <= 0:
            raise UserError(f"meta.json: wheel sub-parts need a positive gear_ratio, got {g!r}")
    return [n for n in SUB_PARTS if n in names]


def has_crank(bike_dir):
    """Whether a bike folder's rideable has pedals (meta.json "has_crank", true when the key is
    absent).  A missing or unreadable meta.json is a UserError naming it: read as "no crank" it made
    `bikes: all` drop the bike from a cyclist dataset without a word."""
    return bool(read_meta(bike_dir).get("has_crank", True))


def parse_keypoints_doc(doc, has_crank=True, required=(), source="keypoints.json"):
    """A keypoints.json object -> (coords {name: (3,) float64}, part_of {name: part}); one
    UserError naming `source` for anything the rig cannot use (wrong frame or units, a missing
    required keypoint, non-finite coordinates, a part list naming an unknown or absent part)."""
    if not isinstance(doc, dict) or not isinstance(doc.get("keypoints"), dict):
        raise UserError(f"{source}: keypoints.json has no 'keypoints' object")
    if doc.get("frame", "canonical") != "canonical" or doc.get("units", "m") != "m":
        raise UserError(f"{source}: keypoints.json must be frame 'canonical', units 'm'")
    kps = doc["keypoints"]
    missing = [k for k in required if k not in kps]
    if missing:
        raise UserError(f"{source}: keypoints.json lacks keypoints {', '.join(missing)}")
    coords = {}
    for k, v in kps.items():
        ok = isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        a = np.asarray(v, dtype=np.float64) if ok else None
        if a is None or not np.isfinite(a).all():
            raise UserError(f"{source}: keypoint {k} must be 3 finite numbers, got {v!r}")
        coords[k] = a
    part_of = {k: "frame" for k in coords}
    listed = doc.get("parts")
    if listed is None:
        listed = {p: [k for k in ks if k in coords] for p, ks in DEFAULT_KEYPOINT_PARTS.items()}
    if not isinstance(listed, dict):
        raise UserError(f"{source}: keypoints.json 'parts' must map part names to keypoint lists")
    for p, ks in listed.items():
        if p not in PARTS:
            raise UserError(f"{source}: keypoints.json 'parts' names unknown part {p!r}")
        if p == "crank" and not has_crank and ks:
            raise UserError(f"{source}: keypoints.json assigns {ks} to a crank this rideable lacks")
        for k in ks:
            if k not in coords:
                raise UserError(f"{source}: keypoints.json 'parts' lists {k!r}, which has no coordinates")
            part_of[k] = p  # a keypoint listed twice sits on the shared axis: either part works
    return coords, part_of


def keypoints_doc(keypoints, parts=None):
    doc = {"frame": "canonical", "units": "m", "keypoints": {k: [float(x) for x in v] for k, v in keypoints.items()}}
    if parts is not None:
        doc["parts"] = {k: list(v) for k, v in parts.items()}
    return doc


def views_dir(bike_dir, part):
    return os.path.join(bike_dir, "views", part)


def gaussians_path(bike_dir, part):
    return os.path.join(bike_dir, "gaussians", part + ".ply")


def view_paths(views_dir, name):
    return {"rgba": os.path.join(views_dir, "rgba", name, FRAME + ".png"),
            "img": os.path.join(views_dir, "img", name, FRAME + ".jpg"),
            "mask": os.path.join(views_dir, "mask", name, FRAME + ".png")}


def view_complete(paths):
    return all(os.path.isfile(p) and os.path.getsize(p) > 0 for p in paths.values())


def derived_images(rgba):
    """(H, W, 4) uint8 straight-alpha RGBA -> (RGB on black (H, W, 3), mask (H, W) 0/255)."""
    rgba = np.asarray(rgba)
    alpha = rgba[..., 3:4].astype(np.float32) / 255.0
    on_black = np.clip(rgba[..., :3].astype(np.float32) * alpha + 0.5, 0, 255).astype(np.uint8)
    mask = (rgba[..., 3] > MASK_ALPHA).astype(np.uint8) * 255
    return on_black, mask


def write_derived(paths, rgba=None, rendered_png=None):
    """Write paths["img"] and paths["mask"] derived from one RGBA, then paths["rgba"] last (its
    presence plus the other two marks a view complete, so a killed run redoes it), atomically.

    rgba: (H, W, 4) uint8 array, or rendered_png: a finished RGBA PNG that is moved into place."""
    from PIL import Image

    if rgba is None:
        rgba = np.asarray(Image.open(rendered_png).convert("RGBA"))
    on_black, mask = derived_images(rgba)
    with atomic_path(paths["img"]) as tmp:
        Image.fromarray(on_black).save(tmp, format="JPEG", quality=95)
    with atomic_path(paths["mask"]) as tmp:
        Image.fromarray(mask).save(tmp, format="PNG")
    os.makedirs(os.path.dirname(paths["rgba"]) or ".", exist_ok=True)
    if rendered_png is not None:
        os.replace(rendered_png, paths["rgba"])
    else:
        with atomic_path(paths["rgba"]) as tmp:
            Image.fromarray(np.asarray(rgba, dtype=np.uint8)).save(tmp, format="PNG")
    return paths


def write_view(views_dir, name, rgba=None, rendered_png=None):
    """One view of a views folder in the layout above (see write_derived)."""
    return write_derived(view_paths(views_dir, name), rgba, rendered_png)


def write_views_meta(views_dir, cameras, transforms=None, keypoints=None):
    """cameras.json (+ transforms.json, + the part's keypoints.json) of a views folder."""
    write_json(os.path.join(views_dir, "cameras.json"), cameras)
    if transforms is not None:
        write_json(os.path.join(views_dir, "transforms.json"), transforms)
    if keypoints is not None:
        write_json(os.path.join(views_dir, "keypoints.json"), keypoints_doc(keypoints))


# -- relighting passes (docs/relighting.md) --------------------------------------------------------
# Per view, beside rgba/img/mask, from the same Cycles render:
#   <bike>/views/<part>/albedo/cameraNNNN/0000.png  Cycles "Diffuse Color", linear, stored sRGB-encoded
#                                                   (the view transform every colour PNG here uses)
#   <bike>/views/<part>/normal/cameraNNNN/0000.png  Cycles "Normal", canonical world frame, stored as
#                                                   round((n + 1) / 2 * 255)
#   <bike>/views/<part>/gloss/cameraNNNN/0000.png   Cycles "Glossy Color", linear, stored sRGB-encoded
# All are RGB and, like the passes they come from, averaged over the pixel's samples with the
# empty film counting as 0: premultiplied by coverage, as the rasterizer composites.
PASSES = ("albedo", "normal", "gloss")


def pass_paths(views_dir, name):
    return {p: os.path.join(views_dir, p, name, FRAME + ".png") for p in PASSES}


def srgb_encode(x):
    """Linear [0, 1] -> sRGB-encoded [0, 1] (the piecewise IEC 61966-2-1 curve; Blender's 'Standard')."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_decode(y):
    """sRGB-encoded [0, 1] -> linear [0, 1]."""
    y = np.clip(np.asarray(y, dtype=np.float64), 0.0, 1.0)
    return np.where(y <= 0.04045, y / 12.92, np.power((y + 0.055) / 1.055, 2.4))


def _to8(x):
    return np.clip(np.asarray(x, dtype=np.float64) * 255.0 + 0.5, 0, 255).astype(np.uint8)


def encode_passes(albedo, normal, gloss):
    """(H, W, 3) float passes (colours linear, normal canonical; premultiplied) -> {name: uint8 RGB}."""
    return {"albedo": _to8(srgb_encode(albedo)), "normal": _to8((np.asarray(normal, dtype=np.float64) + 1.0) * 0.5),
            "gloss": _to8(srgb_encode(gloss))}


def write_passes(paths, albedo, normal, gloss):
    """Write pass_paths() images atomically (see encode_passes)."""
    from PIL import Image

    for key, img in encode_passes(albedo, normal, gloss).items():
        with atomic_path(paths[key]) as tmp:
            Image.fromarray(img).save(tmp, format="PNG")
    return paths


def read_passes(paths):
    """pass_paths() -> {"albedo", "normal", "gloss"}: (H, W, 3) float32, colours linear, normal canonical;
    UserError when a file is missing (a folder rendered before the passes existed: rerun render_views)."""
    from PIL import Image

    out = {}
    for key in PASSES:
        p = paths[key]
        if not os.path.isfile(p):
            raise UserError(f"{p}: missing {key} pass (render the views again with render_views to add it)")
        a = np.asarray(Image.open(p).convert("RGB")).astype(np.float64) / 255.0
        out[key] = (a * 2.0 - 1.0 if key == "normal" else srgb_decode(a)).astype(np.float32)
    return out


# Relightable Gaussians: beside gaussians/<part>.ply, gaussians/<part>.relight.npz holds "albedo" (N, 3)
# linear diffuse colour, "gloss" (N, 3) linear glossy colour and "normal" (N, 3) unit normals in the
# part's canonical frame, float32, row i belonging to the PLY's Gaussian i.  Optionally "normal_view"
# (N, 3, 3), same frame: view-dependent normals, Gaussian i's normal seen from the unit direction v
# (from it to the camera) being normalize(normal_i + normal_view_i @ v) (docs/relighting.md).
RELIGHT_KEYS = ("albedo", "normal", "gloss")
RELIGHT_VIEW_KEY = "normal_view"


def relight_path(ply_path):
    return os.path.splitext(os.fspath(ply_path))[0] + ".relight.npz"


def write_relight(ply_path, albedo, normal, gloss, normal_view=None):
    path = relight_path(ply_path)
    arrays = {k: np.asarray(v, np.float32) for k, v in zip(RELIGHT_KEYS, (albedo, normal, gloss))}
    if normal_view is not None:
        arrays[RELIGHT_VIEW_KEY] = np.asarray(normal_view, np.float32)
        if arrays[RELIGHT_VIEW_KEY].shape != (len(arrays["normal"]), 3, 3):
            raise ValueError(f"normal_view {arrays[RELIGHT_VIEW_KEY].shape} != ({len(arrays['normal'])}, 3, 3)")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)
    return path


def read_relight(ply_path, n=None):
    """-> {"albedo", "normal", "gloss"}: (N, 3) float32, and "normal_view" (N, 3, 3) when the file has
    view-dependent normals; UserError when missing or not matching n Gaussians."""
    path = relight_path(ply_path)
    if not os.path.isfile(path):
        raise UserError(f"{path}: missing (fit it with `python -m splatting relight-fit`)")
    try:
        with np.load(path) as z:
            out = {k: z[k] for k in RELIGHT_KEYS}
            view = z[RELIGHT_VIEW_KEY] if RELIGHT_VIEW_KEY in z.files else None
    except (OSError, KeyError, ValueError) as e:
        raise UserError(f"{path}: unreadable relight file ({e})") from None
    shapes = {k: v.shape for k, v in out.items()}
    if any(s != ((n if n is not None else s[0]), 3) for s in shapes.values()) or len(set(shapes.values())) != 1:
        raise UserError(f"{path}: arrays {shapes} do not match {n} Gaussians")
    if view is not None:
        if view.shape != (len(out["normal"]), 3, 3):
            raise UserError(f"{path}: {RELIGHT_VIEW_KEY} {view.shape} does not match {len(out['normal'])} Gaussians")
        out[RELIGHT_VIEW_KEY] = view
    return out

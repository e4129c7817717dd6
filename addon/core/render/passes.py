"""The diffuse-albedo, normal and glossy-colour passes of a Cycles render, read the same way in Blender 3.4 and 5.0.

Why not the compositor: Blender 5.0 replaced scene.node_tree (and the File Output node's slots)
with node groups, so a compositor graph needs two code paths.  Saving the finished Render Result
as an uncompressed multilayer EXR works in both (5.0 only moved the format behind
image_settings.media_type) and holds every enabled pass; `read_exr` below parses it with numpy.
3.4 writes one part with all channels, 5.0 one part per pass; channel names are
"<view layer>.<pass>.<channel>", and 5.0 spells the passes out ("Diffuse Color" for "DiffCol").
"""
import os
import struct

import numpy as np

from .. import frames
from ..contract import bike_folder, temp_name

ALBEDO_NAMES = ("DiffCol", "Diffuse Color")
GLOSS_NAMES = ("GlossCol", "Glossy Color")
NORMAL_NAMES = ("Normal",)
_PIXEL = {0: np.uint32, 1: np.float16, 2: np.float32}  # EXR pixel types UINT, HALF, FLOAT


def enable(view_layer):
    """Turn on the passes this module reads (cheap: Cycles fills them on the camera ray's first hit)."""
    view_layer.use_pass_diffuse_color = True
    view_layer.use_pass_glossy_color = True
    view_layer.use_pass_normal = True


def save_exr(scene, path):
    """Write the last render's every pass to `path` (multilayer EXR, 32-bit float, uncompressed),
    leaving scene.render.image_settings as they were."""
    import bpy

    s = scene.render.image_settings
    saved = {k: getattr(s, k) for k in ("media_type", "file_format", "color_depth", "exr_codec", "color_mode")
             if hasattr(s, k)}
    try:
        if hasattr(s, "media_type"):  # Blender >= 5.0: multilayer is a media type
            s.media_type = "MULTI_LAYER_IMAGE"
        s.file_format = "OPEN_EXR_MULTILAYER"
        s.color_depth = "32"
        s.exr_codec = "NONE"
        bpy.data.images["Render Result"].save_render(path, scene=scene)
    finally:
        for k in ("media_type", "file_format", "color_depth", "exr_codec", "color_mode"):
            if k in saved:
                try:
                    setattr(s, k, saved[k])
                except TypeError:  # an enum value valid only for the other media type
                    pass


def _attrs(buf, pos):
    """One EXR header from pos -> ({name: (type, bytes)}, position after its terminating null)."""
    out = {}
    while buf[pos] != 0:
        end = buf.index(b"\0", pos)
        name = buf[pos:end].decode()
        tend = buf.index(b"\0", end + 1)
        typ = buf[end + 1:tend].decode()
        size = struct.unpack_from("<i", buf, tend + 1)[0]
        out[name] = (typ, buf[tend + 5:tend + 5 + size])
        pos = tend + 5 + size
    return out, pos + 1


def _channels(raw):
    chans, pos = [], 0
    while raw[pos] != 0:
        end = raw.index(b"\0", pos)
        ptype = struct.unpack_from("<i", raw, end + 1)[0]
        chans.append((raw[pos:end].decode(), ptype))
        pos = end + 1 + 16  # pixel type, pLinear + 3 reserved, xSampling, ySampling
    return chans


def read_exr(path):
    """An uncompressed scanline EXR (single- or multi-part) -> {channel name: (H, W) float32}."""
    with open(path, "rb") as f:
        buf = f.read()
    if buf[:4] != b"\x76\x2f\x31\x01":
        raise ValueError(f"{path}: not an OpenEXR file")
    flags = struct.unpack_from("<I", buf, 4)[0]
    if flags & 0x200:
        raise ValueError(f"{path}: tiled EXR is not supported")
    multi = bool(flags & 0x1000)
    pos, headers = 8, []
    while True:
        h, pos = _attrs(buf, pos)
        headers.append(h)
        if not multi or buf[pos] == 0:
            pos += 1 if multi else 0
            break
    out = {}
    for part, h in enumerate(headers):
        if h["compression"][1][0] != 0:
            raise ValueError(f"{path}: compressed EXR (codec {h['compression'][1][0]}), expected NONE")
        x0, y0, x1, y1 = struct.unpack("<4i", h["dataWindow"][1])
        W, H = x1 - x0 + 1, y1 - y0 + 1
        chans = _channels(h["channels"][1])
        n = struct.unpack("<i", h["chunkCount"][1])[0] if "chunkCount" in h else H
        offsets = np.frombuffer(buf, "<u8", n, pos)
        pos += 8 * n
        planes = {c: np.zeros((H, W), np.float32) for c, _ in chans}
        for off in offsets:
            o = int(off) + (4 if multi else 0)  # a multipart chunk starts with its part number
            y, _size = struct.unpack_from("<ii", buf, o)
            o += 8
            for c, t in chans:  # one scanline per chunk without compression, channels in header order
                dt = np.dtype(_PIXEL[t]).newbyteorder("<")
                planes[c][y - y0] = np.frombuffer(buf, dt, W, o)
                o += W * dt.itemsize
        out.update(planes)
    return out


def _find(channels, names, comps):
    for key in channels:
        layer_pass, _, comp = key.rpartition(".")
        if layer_pass.rpartition(".")[2] in names and comp == comps[0]:
            base = key[: -len(comp)]
            return np.stack([channels[base + c] for c in comps], -1)
    raise ValueError(f"no {'/'.join(names)} pass among the EXR channels {sorted(channels)[:12]}")


def view_passes(channels):
    """read_exr() output -> {"albedo": (H, W, 3) linear diffuse colour, "normal": (H, W, 3) canonical frame,
    "gloss": (H, W, 3) linear glossy colour}."""
    return {"albedo": _find(channels, ALBEDO_NAMES, "RGB"),
            "normal": frames.to_canonical(_find(channels, NORMAL_NAMES, "XYZ")),
            "gloss": _find(channels, GLOSS_NAMES, "RGB")}


def write_view_passes(scene, paths):
    """After a render: its albedo, normal and gloss passes -> the bike_folder.pass_paths() PNGs, atomically."""
    exr = temp_name(os.path.splitext(paths["albedo"])[0] + ".exr")  # creates it; removed below
    try:
        save_exr(scene, exr)
        images = view_passes(read_exr(exr))
    finally:
        if os.path.exists(exr):
            os.remove(exr)
    return bike_folder.write_passes(paths, **images)

"""Meshopt-compressed glTF (EXT_meshopt_compression / KHR_meshopt_compression, as gltfpack -c/-cc writes it)
written out again without it, so Blender's glTF importer (which cannot decode meshopt) reads it.

The decoding is meshoptimizer's own (the `meshoptimizer` Python package, its C library through ctypes: an
optional dependency, `pip install meshoptimizer`); this module only re-lays the file: every bufferView's bytes
(decoded where compressed: vertex attributes, triangle indices or index sequences, then the octahedral,
quaternion or exponential filter) go into one binary buffer, images with a URI are embedded beside them, and
the extension leaves extensionsUsed/Required.  Everything else in the JSON (meshes, skins, nodes, materials,
KHR_mesh_quantization, texture extensions) is kept as it was.  The result is a self-contained .glb.
"""
import json
import mimetypes
import os
import struct
from urllib.parse import unquote

import numpy as np

from .errors import UserError

MESHOPT = ("EXT_meshopt_compression", "KHR_meshopt_compression")
PACKAGE = "meshoptimizer"  # the PyPI package that decodes them


def decoder():
    """The meshoptimizer package, or None when it is not installed."""
    try:
        import meshoptimizer
    except ImportError:
        return None
    return meshoptimizer


def read_glb_or_gltf(path):
    """(json dict, binary chunk bytes or None) of a .glb or .gltf."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"glTF":
        return json.loads(data.decode("utf-8")), None
    off, g, bin_chunk = 12, None, None
    while off + 8 <= len(data):
        n, kind = struct.unpack_from("<II", data, off)
        chunk = data[off + 8:off + 8 + n]
        if kind == 0x4E4F534A:
            g = json.loads(chunk.decode("utf-8"))
        elif kind == 0x004E4942 and bin_chunk is None:
            bin_chunk = chunk
        off += 8 + n + (-n % 4)
    if g is None:
        raise UserError(f"{path}: corrupt .glb (no JSON chunk)")
    return g, bin_chunk


def _buffers(g, bin_chunk, folder, path):
    out = []
    for i, b in enumerate(g.get("buffers") or []):
        uri = b.get("uri")
        if uri is None:
            # the GLB's own chunk (buffer 0), or a fallback buffer of meshopt data with no bytes
            out.append(bin_chunk if i == 0 and bin_chunk is not None else None)
        elif uri.startswith("data:"):
            import base64
            out.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            f = os.path.join(folder, unquote(uri))
            if not os.path.isfile(f):
                raise UserError(f"{path}: buffer file {uri!r} not found next to it")
            out.append(open(f, "rb").read())
    return out


def _decode_view(mo, ext, buffers, path):
    src = buffers[ext["buffer"]]
    if src is None:
        raise UserError(f"{path}: meshopt data refers to a buffer without bytes")
    start = int(ext.get("byteOffset", 0))
    data = np.frombuffer(src, np.uint8, int(ext["byteLength"]), start)
    count, stride = int(ext["count"]), int(ext["byteStride"])
    mode, filt = ext.get("mode", "ATTRIBUTES"), ext.get("filter", "NONE")
    try:
        if mode == "ATTRIBUTES":
            out = mo.decode_vertex_buffer(count, stride, data, dtype=np.dtype((np.void, stride)))
            raw = np.frombuffer(out.tobytes(), np.uint8).copy()
            if filt != "NONE":
                fn = {"OCTAHEDRAL": mo.decode_filter_oct, "QUATERNION": mo.decode_filter_quat,
                      "EXPONENTIAL": mo.decode_filter_exp}.get(filt)
                if fn is None:
                    raise UserError(f"{path}: meshopt filter {filt!r} is not one this decoder knows")
                raw = fn(raw, count, stride)
            return raw.tobytes()
        fn = {"TRIANGLES": mo.decode_index_buffer, "INDICES": mo.decode_index_sequence}.get(mode)
        if fn is None:
            raise UserError(f"{path}: meshopt mode {mode!r} is not one this decoder knows")
        return fn(count, stride, data).tobytes()[:count * stride]  # decoded as stride-byte indices
    except (RuntimeError, ValueError) as e:
        raise UserError(f"{path}: corrupt meshopt data ({e})") from None


def decompress(path, out):
    """Write `path` (a .glb/.gltf using meshopt compression) to `out` as a self-contained .glb without it."""
    mo = decoder()
    if mo is None:
        raise UserError(f"{path}: meshopt-compressed; `pip install {PACKAGE}` to decode it")
    g, bin_chunk = read_glb_or_gltf(path)
    folder = os.path.dirname(os.path.abspath(path))
    buffers = _buffers(g, bin_chunk, folder, path)
    blob = bytearray()

    def put(b):
        blob.extend(b"\0" * (-len(blob) % 16))
        off = len(blob)
        blob.extend(b)
        return off

    for bv in g.get("bufferViews") or []:
        ext = next(((k, bv["extensions"][k]) for k in MESHOPT if k in (bv.get("extensions") or {})), None)
        if ext is not None:
            data = _decode_view(mo, ext[1], buffers, path)
            del bv["extensions"][ext[0]]
            if not bv["extensions"]:
                del bv["extensions"]
        else:
            src = buffers[bv["buffer"]]
            if src is None:
                raise UserError(f"{path}: bufferView refers to a buffer without bytes")
            o = int(bv.get("byteOffset", 0))
            data = bytes(src[o:o + int(bv["byteLength"])])
        bv.update(buffer=0, byteOffset=put(data), byteLength=len(data))
    for im in g.get("images") or []:
        uri = im.get("uri")
        if uri is None or uri.startswith("data:"):
            continue
        f = os.path.join(folder, unquote(uri))
        if not os.path.isfile(f):
            continue  # the importer will look for it by name and say so (rider_colours)
        g.setdefault("bufferViews", []).append({"buffer": 0, "byteOffset": put(open(f, "rb").read()),
                                                "byteLength": os.path.getsize(f)})
        im.update(bufferView=len(g["bufferViews"]) - 1,
                  mimeType=im.get("mimeType") or mimetypes.guess_type(f)[0] or "image/png")
        del im["uri"]
    blob.extend(b"\0" * (-len(blob) % 4))
    g["buffers"] = [{"byteLength": len(blob)}]
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in g:
            g[key] = [e for e in g[key] if e not in MESHOPT]
            if not g[key]:
                del g[key]
    js = json.dumps(g, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + 8 + len(blob)
    with open(out, "wb") as f:
        f.write(b"glTF" + struct.pack("<II", 2, total) + struct.pack("<II", len(js), 0x4E4F534A) + js
                + struct.pack("<II", len(blob), 0x004E4942) + bytes(blob))
    return out

"""Which glTF extensions a model file needs that Blender's glTF importer cannot read (pure Python).

Blender's importer (3.4 .. 5.0) decodes Draco (KHR_draco_mesh_compression, its bundled decoder),
KHR_mesh_quantization and EXT_texture_webp itself; meshopt-compressed buffers and Basis Universal (KTX2)
textures it refuses deep inside with a traceback.  `unreadable_extensions(path)` reads the file's JSON
(the .gltf, or a .glb's first chunk) and names them, so `rider import` can refuse in one line before
Blender starts, saying how to get a file it reads.  `rider import` decodes meshopt itself when the
meshoptimizer package is installed (gltf_meshopt.py).
"""
import json
import os
import struct

from .errors import UserError

# extension -> how to get a file without it
MESHOPT_ADVICE = ("`pip install meshoptimizer` and `rider import` decodes it, or export the model again without "
                  "meshopt compression (or decompress it: npm @gltf-transform/cli `gltf-transform copy`)")
NOT_READ = {
    "EXT_meshopt_compression": MESHOPT_ADVICE,
    "KHR_meshopt_compression": MESHOPT_ADVICE,
    "KHR_texture_basisu": "convert its KTX2 textures to PNG (e.g. KTX-Software's `ktx extract`) or export again "
                          "with PNG/JPEG textures",
}


def gltf_json(path):
    """The JSON of a .gltf or .glb file; UserError when it is not one."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise UserError(f"{path}: truncated .glb (no JSON chunk)")
        n, kind = struct.unpack_from("<II", data, 12)
        if kind != 0x4E4F534A:
            raise UserError(f"{path}: corrupt .glb (first chunk is not JSON)")
        text = data[20:20 + n]
    else:
        text = data
    try:
        return json.loads(text.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise UserError(f"{path}: not a glTF file (its JSON does not parse: {str(e)[:80]})") from None


def unreadable_extensions(path):
    """[(extension, advice)] for the extensions `path` requires (or uses without fallback) that
    Blender's importer does not read; [] for other model formats."""
    if not str(path).lower().endswith((".glb", ".gltf", ".vrm")) or not os.path.isfile(path):
        return []
    g = gltf_json(path)
    if not isinstance(g, dict):
        raise UserError(f"{path}: not a glTF file (its JSON is not an object)")
    need = set(g.get("extensionsRequired") or [])
    for b in g.get("bufferViews") or []:  # meshopt with a fallback buffer is still unreadable to Blender
        if isinstance(b, dict) and "EXT_meshopt_compression" in (b.get("extensions") or {}):
            need.add("EXT_meshopt_compression")
    return [(e, NOT_READ[e]) for e in sorted(need) if e in NOT_READ]


def check_readable(path, decoded=()):
    """UserError naming the first extension Blender cannot read (other than those in `decoded`, which the
    caller decodes before Blender reads the file), and what to do."""
    bad = [(e, a) for e, a in unreadable_extensions(path) if e not in decoded]
    if bad:
        ext, advice = bad[0]
        raise UserError(f"{path}: uses the glTF extension {ext}, which Blender's glTF importer cannot read: "
                        f"{advice}")

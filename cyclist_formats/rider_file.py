"""The imported-rider file (`rider.npz`): a user's rigged human reduced to the 24 SMPL joints, numpy only.

Written by the Blender side (`blender_scripts/import_rider.py`, `addon/core/rider/rider_rig.py`), read by
torch (`splatting/rider/imported.py`), so neither side needs the other's libraries.  Arrays, all in the
canonical frame (docs/contract.md: X forward, Y up, Z to the rider's right, metres), T-pose, soles on
Y = 0, pelvis joint at X = Z = 0, exactly like the body-model riders:

| key | shape, type | meaning |
| --- | --- | --- |
| vertices | (V,3) float32 | rest (T-pose) mesh |
| faces | (F,3) int32 | triangles, indices into vertices |
| joints | (24,3) float32 | SMPL joints (bone_map.SMPL_JOINTS order) at their bones' heads |
| weights | (V,24) float32 | skinning weights over the 24 joints, rows sum to 1 |
| colors | (V,3) float32 | sRGB in [0, 1], the textures / material colours sampled per vertex |
| meta | () str | JSON: format, version, id, source, scheme, bone_map, rest_pose, swings_deg, ... |
| uv | (F,3,2) float32, optional | each triangle corner's texture coordinate (v up, Blender's convention) |
| face_texture | (F,) int16, optional | texture_K drawn on the face, -1 = its vertex colours |
| texture_K | (H,W,3) uint8, optional | the K-th texture, sRGB, row 0 at the bottom (v = 0) |

The optional arrays keep texture detail finer than the vertices for the avatar's training renders.

Checks on read: every key present, shapes agreeing, finite values, weights >= 0 summing to 1 (1e-3),
face indices in range, colours in [0, 1]; anything else is one UserError line naming the file.
"""
import json
import os
import re

import numpy as np

from .atomic import atomic_path
from .bone_map import SMPL_JOINTS
from .errors import UserError

FORMAT = "articcyclists-rider"
VERSION = 1
FILE_NAME = "rider.npz"
ARRAYS = ("vertices", "faces", "joints", "weights", "colors")
_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


def check_rider_id(rider_id, flag="--id"):
    """A rider id usable as a folder name and in YAML configs; UserError otherwise."""
    if not isinstance(rider_id, str) or not _ID.match(rider_id):
        raise UserError(f"{flag} must be 1-64 letters, digits, '_', '.' or '-' (starting with a letter or "
                        f"digit), got {rider_id!r}")
    return rider_id


def _check(path, a, meta):
    def bad(msg):
        raise UserError(f"{path}: not a usable rider file: {msg}")

    v, f, j, w, c = (a[k] for k in ARRAYS)
    if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4:
        bad(f"vertices must be (V,3) with V >= 4, got {v.shape}")
    n = len(v)
    if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        bad(f"faces must be (F,3), got {f.shape}")
    if not np.issubdtype(f.dtype, np.integer) or f.min() < 0 or f.max() >= n:
        bad(f"faces must be integer indices below {n}")
    if j.shape != (len(SMPL_JOINTS), 3):
        bad(f"joints must be (24,3), got {j.shape}")
    if w.shape != (n, len(SMPL_JOINTS)):
        bad(f"weights must be ({n},24), got {w.shape}")
    if c.shape != (n, 3):
        bad(f"colors must be ({n},3), got {c.shape}")
    for k in ("vertices", "joints", "weights", "colors"):
        if not np.isfinite(a[k]).all():
            bad(f"{k} hold NaN or infinite values")
    if w.min() < 0 or np.abs(w.sum(1) - 1).max() > 1e-3:
        bad("weights must be >= 0 and sum to 1 per vertex")
    if c.min() < 0 or c.max() > 1:
        bad("colors must lie in [0, 1]")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        bad(f"meta.format is not {FORMAT!r}")
    if meta.get("version") != VERSION:
        bad(f"version {meta.get('version')!r}, this code reads version {VERSION}")
    if not isinstance(meta.get("id"), str) or not meta["id"]:
        bad("meta.id must be a non-empty string")


def _check_textures(path, a, n_faces):
    def bad(msg):
        raise UserError(f"{path}: not a usable rider file: {msg}")

    if "uv" not in a and "face_texture" not in a:
        return 0
    uv, ft = a.get("uv"), a.get("face_texture")
    if uv is None or ft is None:
        bad("uv and face_texture come together")
    if uv.shape != (n_faces, 3, 2) or not np.isfinite(uv).all():
        bad(f"uv must be finite ({n_faces},3,2), got {uv.shape}")
    n_tex = len([k for k in a if k.startswith("texture_")])
    if ft.shape != (n_faces,) or not np.issubdtype(ft.dtype, np.integer) or ft.min() < -1 or ft.max() >= n_tex:
        bad(f"face_texture must be ({n_faces},) indices in [-1, {n_tex})")
    for k in range(n_tex):
        t = a.get(f"texture_{k}")
        if t is None or t.ndim != 3 or t.shape[2] != 3 or t.dtype != np.uint8 or min(t.shape[:2]) < 1:
            bad(f"texture_{k} must be (H,W,3) uint8 and textures numbered from 0")
    return n_tex


def write_rider_file(path, vertices, faces, joints, weights, colors, meta, uv=None, face_texture=None,
                     textures=()):
    """Write `path` (.npz) atomically after the same checks the reader makes; returns path.
    uv (F,3,2) + face_texture (F,) + textures [(H,W,3) uint8] are the optional texture layer."""
    path = os.fspath(path)
    if not path.endswith(".npz"):
        raise UserError(f"rider file must end in .npz, got {path}")
    a = {"vertices": np.asarray(vertices, np.float32), "faces": np.asarray(faces, np.int32),
         "joints": np.asarray(joints, np.float32), "weights": np.asarray(weights, np.float32),
         "colors": np.asarray(colors, np.float32)}
    if uv is not None or face_texture is not None:
        a["uv"] = None if uv is None else np.asarray(uv, np.float32)
        a["face_texture"] = None if face_texture is None else np.asarray(face_texture, np.int16)
        a.update({f"texture_{k}": np.asarray(t, np.uint8) for k, t in enumerate(textures)})
    meta = dict(meta, format=FORMAT, version=VERSION)
    _check(path, a, meta)
    _check_textures(path, a, len(a["faces"]))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:  # a file object: np.savez would append '.npz' to the temp name
            np.savez_compressed(fh, meta=np.array(json.dumps(meta)), **a)
    return path


def read_meta(path):
    """Only the metadata dict (cheap: the arrays are not decompressed)."""
    try:
        with np.load(os.fspath(path), allow_pickle=False) as z:
            return json.loads(str(z["meta"]))
    except FileNotFoundError:
        raise UserError(f"rider file not found: {path}") from None
    except (OSError, ValueError, KeyError, EOFError) as e:
        raise UserError(f"{path}: not a rider file ({type(e).__name__}: {e})") from None


def read_rider_file(path):
    """(arrays dict: ARRAYS and any texture layer, meta dict); UserError on a missing or malformed file."""
    path = os.fspath(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in ARRAYS + ("meta",) if k not in z.files]
            if missing:
                raise UserError(f"{path}: not a rider file, missing {', '.join(missing)}")
            a = {k: z[k] for k in z.files if k != "meta"}
            meta = json.loads(str(z["meta"]))
    except FileNotFoundError:
        raise UserError(f"rider file not found: {path}") from None
    except (OSError, ValueError, EOFError) as e:
        raise UserError(f"{path}: not a rider file ({type(e).__name__}: {e})") from None
    _check(path, a, meta)
    _check_textures(path, a, len(a["faces"]))
    return a, meta


def textures_of(a):
    """The texture arrays of a read rider file, in order (empty when it has no texture layer)."""
    return [a[f"texture_{k}"] for k in range(len([k for k in a if k.startswith("texture_")]))]

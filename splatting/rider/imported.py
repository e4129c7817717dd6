"""Riders imported from the user's own rigged humans (`python -m splatting rider import`), as body.Rider.

The Blender side (blender_scripts/import_rider.py) writes a `rider.npz` (cyclist_formats.rider_file):
the T-posed mesh in the canonical frame, the 24 SMPL joints, weights over them and vertex colours
sampled from the textures.  Here it becomes the same `Rider` the anny and SMPL bodies give, so the
avatar build, the IK, the motions and the datasets take it unchanged.

Where they live: `IMPORTED_DIR/<id>/rider.npz` (data/imported_riders/, git-ignored like every built
asset); `imported_entries()` lists them as roster entries {id, body: imported, rider_file, ...}.  A
roster entry in blend_assets/riders.yaml with `body: imported` and `rider_file:` (a path from the
repository root or absolute) works the same way.
"""
import os
from pathlib import Path

import numpy as np
import torch

from cyclist_formats import rider_file
from cyclist_formats.errors import UserError
from splatting import paths
from splatting.rider.body import Rider

IMPORTED_DIR = paths.DATA / "imported_riders"


def rider_path(rider_id, folder=None):
    return Path(folder or IMPORTED_DIR) / rider_id / rider_file.FILE_NAME


def imported_entries(folder=None):
    """Roster entries for every rider file under `folder` (default IMPORTED_DIR), sorted by id."""
    folder = Path(folder or IMPORTED_DIR)
    if not folder.is_dir():
        return []
    out = []
    for d in sorted(folder.iterdir()):
        f = d / rider_file.FILE_NAME
        if not f.is_file():
            continue
        meta = rider_file.read_meta(f)
        if meta.get("id") != d.name:
            raise UserError(f"{f}: holds rider {meta.get('id')!r} but sits in folder {d.name!r}")
        out.append({"id": d.name, "body": "imported", "rider_file": str(f), "source": meta.get("source", "?"),
                    "scheme": meta.get("scheme", "?"), "rest_pose": meta.get("rest_pose", "?"),
                    "height_m": float(meta.get("height_m", 0.0))})
    return out


def load_imported_rider(path, rider_id=None, spec=None):
    """Rider from a rider file (UserError if missing or malformed)."""
    a, meta = rider_file.read_rider_file(path)
    f32 = lambda x: torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))  # noqa: E731
    v = a["vertices"]
    s = dict(spec or {}, id=rider_id or meta["id"], body="imported", rider_file=os.fspath(path),
             source=meta.get("source"), scheme=meta.get("scheme"), rest_pose=meta.get("rest_pose"))
    s["height_m"] = float(v[:, 1].max() - v[:, 1].min())
    return Rider(id=s["id"], vertices=f32(v), faces=torch.from_numpy(a["faces"].astype(np.int64)),
                 joints=f32(a["joints"]), weights=f32(a["weights"]), colors=f32(a["colors"]),
                 height_m=s["height_m"], spec=s)


def rider_from_spec(spec):
    """Rider for a roster entry with `body: imported` and `rider_file:`."""
    p = spec.get("rider_file")
    if not isinstance(p, str) or not p:
        raise UserError(f"rider {spec.get('id')!r}: 'body: imported' needs a 'rider_file' path")
    path = Path(p).expanduser()
    if not path.is_absolute():
        path = paths.ROOT / path
    return load_imported_rider(path, spec.get("id"), spec)

"""What a trained avatar wears: <avatar folder>/look.json, written by `rider-avatar` (avatar_build.py)
before the rest mesh is exported, so it holds the look (looks.py) the training views were rendered in.

    {"rider": "<roster id>", "look": {"top_pattern": ..., "hair": ..., "helmet": ..., "bag": ..., ...}}

"look" is null for a body without a roster look (smpl, imported).  The roster look of a rider is not
enough to know what its avatar wears: an avatar trained before the looks existed, or before its
roster entry changed, holds another one in its Gaussians.  Datasets that draw accessories per
instance (splatting/cyclist/accessories.py) read this record and refuse an avatar without one.
"""
import json
import os

from cyclist_formats.atomic import write_json
from cyclist_formats.errors import UserError
from splatting.rider.looks import LOOK_FIELDS, look_of, validate_look

LOOK_NAME = "look.json"


def look_record(rider):
    """The record of an avatar trained on rider's rest mesh (body.Rider, its look as dressed)."""
    return {"rider": rider.id, "look": None if rider.undressed is None else look_of(rider.spec)}


def write_look(folder, rider):
    """<folder>/look.json for rider, written atomically."""
    write_json(os.path.join(folder, LOOK_NAME), look_record(rider))


def read_look(folder):
    """The record in <folder>/look.json, or None when the folder has none; UserError naming the file
    when it cannot be read or is not a record (a corrupt file is not taken for a missing one)."""
    path = os.path.join(folder, LOOK_NAME)
    if not os.path.isfile(path):
        return None
    try:
        with open(path, encoding="utf-8") as f:
            rec = json.load(f)
    except (OSError, ValueError) as e:
        raise UserError(f"cannot read {path}: {e}")
    why = _problem(rec)
    if why:
        raise UserError(f"{path}: {why}")
    return rec


def _problem(rec):
    """The first problem of a look.json record (a string) or None."""
    if not isinstance(rec, dict) or not isinstance(rec.get("rider"), str) or "look" not in rec:
        return 'not a look record {"rider": id, "look": {...} or null}'
    look = rec["look"]
    if look is None:
        return None
    missing = [k for k in LOOK_FIELDS if not isinstance(look, dict) or k not in look]
    return f"look lacks {', '.join(missing)}" if missing else validate_look(look)

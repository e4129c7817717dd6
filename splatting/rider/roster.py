"""The rider roster (`blend_assets/riders.yaml`): selectable people and their anny phenotypes."""
import functools
import re
from pathlib import Path

from cyclist_formats.errors import UserError
from cyclist_formats.text_files import read_yaml
from splatting import paths
from splatting.rider.body import build_rider
from splatting.rider import smpl_body
from splatting.rider.imported import imported_entries, rider_from_spec
from splatting.rider.looks import look_of, validate_look

ROSTER_PATH = paths.BLEND_ASSETS / "riders.yaml"
PHENOTYPE_KEYS = ("gender", "age", "muscle", "weight", "height", "proportions")
COLOR_KEYS = ("skin", "top", "bottom", "shoes", "helmet")
_HEX = re.compile(r"^#[0-9a-fA-F]{6}$")


def load_roster(path=ROSTER_PATH):
    """List of rider dicts, validated (UserError on a bad file)."""
    path = Path(path)
    data = read_yaml(path, "rider roster", missing=f"rider roster not found: {path}", invalid="bad YAML in {path}: {error}")
    riders = (data or {}).get("riders") if isinstance(data, dict) else None
    if not isinstance(riders, list) or not riders:
        raise UserError(f"{path}: expected a top-level 'riders:' list")
    seen = set()
    for r in riders:
        rid = r.get("id") if isinstance(r, dict) else None
        if not isinstance(rid, str) or not rid:
            raise UserError(f"{path}: every rider needs a string 'id'")
        if rid in seen:
            raise UserError(f"{path}: duplicate rider id {rid!r}")
        seen.add(rid)
        if r.get("body") == "smpl":  # a user-supplied SMPL model (smpl_body.py): no anny phenotype
            if not isinstance(r.get("model_path"), str) or not r["model_path"]:
                raise UserError(f"{path}: rider {rid}: body: smpl needs a 'model_path' string")
            continue
        if r.get("body") == "imported":  # a user's rigged human (imported.py): its file holds the body
            if not isinstance(r.get("rider_file"), str) or not r["rider_file"]:
                raise UserError(f"{path}: rider {rid}: body: imported needs a 'rider_file' string")
            continue
        ph = r.get("phenotype") or {}
        for k in PHENOTYPE_KEYS:
            v = ph.get(k)
            if not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
                raise UserError(f"{path}: rider {rid}: phenotype.{k} must be a number in [0, 1]")
        cols = r.get("colors") or {}
        for k in COLOR_KEYS:
            if not isinstance(cols.get(k), str) or not _HEX.match(cols[k]):
                raise UserError(f"{path}: rider {rid}: colors.{k} must be '#rrggbb'")
        if not isinstance(r.get("height_m"), (int, float)):
            raise UserError(f"{path}: rider {rid}: height_m must be a number")
        if "look" in r:  # optional: fields that override the look drawn from the id (looks.py)
            problem = validate_look(r["look"])
            if problem:
                raise UserError(f"{path}: rider {rid}: {problem}")
    return riders


def all_riders(path=ROSTER_PATH, imported_dir=None):
    """The roster file's riders, then the imported ones (data/imported_riders/, `rider import`);
    an imported id that the file already has is an error rather than a silent shadow."""
    riders = load_roster(path)
    ids = {r["id"] for r in riders}
    for e in imported_entries(imported_dir):
        if e["id"] in ids:
            raise UserError(f"imported rider {e['id']!r} ({e['rider_file']}) has the id of a roster rider in {path}")
        riders.append(e)
    return riders


def get_spec(rider_id, path=ROSTER_PATH):
    riders = all_riders(path)
    for r in riders:
        if r["id"] == rider_id:
            return r
    ids = ", ".join(r["id"] for r in riders)
    raise UserError(f"unknown rider id {rider_id!r} (known: {ids})")


def describe(r):
    """One line, id first."""
    if r.get("body") == "smpl":
        return f"{r['id']}  SMPL model {r['model_path']} ({r.get('gender', 'neutral')})"
    if r.get("body") == "imported":
        h = f"{r['height_m']:.2f} m  " if isinstance(r.get("height_m"), (int, float)) else ""
        return f"{r['id']}  imported {h}from {r.get('source', r['rider_file'])} ({r.get('scheme', '?')} rig)"
    lk = look_of(r)
    helmet = f"helmet {r['colors']['helmet']}" if lk["helmet"] else "no helmet"
    return (f"{r['id']}  {r['sex']:<6} {r['age_years']:>2} y  {r['height_m']:.2f} m  "
            f"{r['build']:<8} top {r['colors']['top']} ({lk['top_pattern']}) bottom {r['colors']['bottom']} "
            f"({lk['legs']})  hair {lk['hair']}  {helmet}{'  backpack' if lk['bag'] == 'backpack' else ''}")


@functools.lru_cache(maxsize=16)
def load_rider(rider_id):
    """The roster's rider `rider_id` (UserError if unknown), built by its body model: anny
    (splatting.rider.body), the user's own SMPL file via smplx (splatting.rider.smpl_body) or the
    user's rigged human imported by `rider import` (splatting.rider.imported).  Cached per process."""
    spec = get_spec(rider_id)
    if spec.get("body") == "imported":
        return rider_from_spec(spec)
    if spec.get("body", "anny") == "smpl":
        return smpl_body.rider_from_spec(spec)
    return build_rider(spec)

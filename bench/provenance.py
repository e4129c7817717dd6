"""Where each benchmark number came from: cache keys for reused artefacts and a provenance record
per results key.

A reused artefact (Blender renders, a relight fit, an earlier training run) is reused only when the
key of what made it matches: the inputs' content hashes, the settings and the version of the code
that made it (code_version: a hash of the source files, so an edit invalidates what it made).
results["provenance"][key] says, for every results key, whether it was measured in this run
("fresh") or read back ("reused"), from which assets, and any fallback taken;
results["not_measured"][key] names the reason a stage measured nothing (report.md shows it).
"""
import functools
import hashlib
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
META = ("provenance", "not_measured")   # results keys that are bookkeeping, not measurements
SOURCE_SUFFIXES = (".py", ".cpp", ".h", ".cu", ".json", ".yaml")


def file_hash(path):
    """sha256 (hex, 16 chars) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def tree_hash(folder, suffixes=None):
    """sha256 over every file under folder (relative path + bytes), optionally only those ending in
    suffixes; a missing folder hashes as 'missing'."""
    if not os.path.isdir(folder):
        return "missing"
    h = hashlib.sha256()
    for d, dirs, files in os.walk(folder):
        dirs[:] = sorted(x for x in dirs if x not in ("__pycache__", "_build"))
        for f in sorted(files):
            if suffixes and not f.endswith(suffixes):
                continue
            p = os.path.join(d, f)
            h.update(os.path.relpath(p, folder).encode() + b"\0" + file_hash(p).encode())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=None)
def code_version(*paths):
    """A hash of the source files under ROOT/paths (folders or files) that made an artefact."""
    h = hashlib.sha256()
    for rel in sorted(paths):
        p = os.path.join(ROOT, rel)
        h.update(rel.encode() + b"\0" + (file_hash(p) if os.path.isfile(p) else tree_hash(p, SOURCE_SUFFIXES)).encode())
    return h.hexdigest()[:16]


# the code behind a Blender render of a bike or rider (the add-on's render and pose, the file formats)
RENDER_CODE = ("addon", "blender_scripts", "cyclist_formats")


def bike_assets(bike_dir):
    """What a bike's Blender render depends on: its folder (absolute) and its model files' hashes."""
    bike_dir = os.path.abspath(bike_dir)
    return {"bike": bike_dir, **{f: file_hash(os.path.join(bike_dir, f)) if os.path.isfile(os.path.join(bike_dir, f))
                                 else "missing" for f in ("bike.blend", "keypoints.json", "meta.json")}}


def record(results, key, status="fresh", **info):
    """Provenance of results[key]: status 'fresh' (measured in this run) or 'reused' (read back from an
    earlier run whose key matched), plus assets, fallbacks and what was reused."""
    if status not in ("fresh", "reused", "partly reused"):
        raise ValueError(f"provenance status {status!r}")
    results.setdefault("provenance", {}).setdefault(key, {}).update(status=status, **info)


def not_measured(results, key, reason):
    """A key this run did not measure, and why (report.md: 'not measured: <reason>')."""
    results.setdefault("not_measured", {})[key] = reason


def measured_keys(results):
    return [k for k in results if k not in META]


# the code behind a relight fit (its fitter, renderer and Gaussians)
FIT_CODE = ("splatting/relight", "splatting/raster", "splatting/gaussians", "cyclist_formats")


def key_matches(path, key):
    """Whether the key file at path records exactly `key` (JSON-equal); False when missing or unreadable."""
    import json
    try:
        with open(path) as f:
            return json.load(f) == json.loads(json.dumps(key, default=str))
    except (OSError, ValueError):
        return False


def write_key(path, key):
    import json

    from cyclist_formats.atomic import write_json
    write_json(path, json.loads(json.dumps(key, default=str)))


def relight_fit_key(ply, views_dir, cfg):
    """What a relight fit depends on: the Gaussians file's bytes, its training views, the fit settings
    and the fitting code (a changed Gaussians file with the same count is caught too)."""
    from pydantic import BaseModel

    from cyclist_formats.typed_config import record_of
    settings = record_of(cfg) if isinstance(cfg, BaseModel) else repr(cfg)
    return {"gaussians": file_hash(ply), "views": tree_hash(views_dir), "settings": settings,
            "code": code_version(*FIT_CODE)}


def relight_fit_is_current(ply, views_dir, cfg):
    """(current, key path, key): current when <part>.relight.npz reads and its .key.json matches."""
    from cyclist_formats import bike_folder
    key = relight_fit_key(ply, views_dir, cfg)
    path = bike_folder.relight_path(ply) + ".key.json"
    try:
        bike_folder.read_relight(ply)
    except bike_folder.UserError:
        return False, path, key
    return key_matches(path, key), path, key

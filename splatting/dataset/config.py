"""Dataset configuration: YAML -> a validated, fully resolved dict (defaults filled in).

The fields, their defaults and ranges are the models of splatting/dataset/config_models.py; every
error names the field it is about in one line: `config field 'views.azimuth_deg': expected
[min, max] ...`.  Unknown fields are errors too (a typo would otherwise silently fall back to a
default).  The resolved config (asset lists expanded) is stored beside the dataset; a resumed run
must resolve to the same one.
"""
import copy
import os

from cyclist_formats import bike_folder, typed_config
from cyclist_formats.errors import UserError
from cyclist_formats.text_files import read_yaml
from splatting import paths
from splatting.dataset import lighting
from splatting.dataset.backgrounds import list_images
from splatting.dataset.config_models import DatasetConfig
from splatting.rider.roster import all_riders

PRESET_DIR = str(paths.BLEND_ASSETS / "datasets")
DEFAULTS = DatasetConfig().model_dump()


def _err(field, msg):
    return typed_config.field_error(field, msg)


def load_yaml(path):
    data = read_yaml(path, "config file", missing=f"no such config file: {path}")
    return {} if data is None else data


def preset_path(name):
    p = os.path.join(PRESET_DIR, f"{name}.yaml")
    if not os.path.isfile(p):
        known = sorted(f[:-5] for f in os.listdir(PRESET_DIR) if f.endswith(".yaml")) if os.path.isdir(PRESET_DIR) else []
        raise UserError(f"unknown preset {name!r} (known: {', '.join(known)})")
    return p


def validate(raw):
    """Raw mapping (from YAML) -> config dict with defaults, checked field by field (DatasetConfig):
    the fields in declaration order, values as written."""
    return typed_config.validate(DatasetConfig, raw).model_dump()


def resolve_assets(cfg):
    """Expand 'all' and check that every rider and bike exists (config field named on failure)."""
    cfg = copy.deepcopy(cfg)
    if cfg["mode"] == "frames":
        from splatting.dataset.frames.source import locate, open_folder
        cfg["frames"] = locate(cfg["frames"])
        open_folder(cfg["frames"])  # every frame's calib, labels, plane and scan size, before any work
    if cfg["mode"] in ("cyclist", "street", "frames"):
        known = [r["id"] for r in all_riders()]
        riders = known if cfg["riders"] == "all" else cfg["riders"]
        bad = [r for r in riders if r not in known]
        if bad:
            raise _err("riders", f"unknown rider ids {bad} (known: {', '.join(known)})")
        cfg["riders"] = list(riders)
    else:
        cfg["riders"] = []
    b = cfg["backgrounds"]
    if "images" in b["kinds"] and b["image_files"] is None:
        b["image_files"] = [os.path.abspath(f) for f in list_images(b["images_dir"])]
    if "scene" in b["kinds"] and not os.path.isfile(b["scene_ply"]):
        raise _err("backgrounds.scene_ply", f"no such file {b['scene_ply']!r}")
    root = cfg["bikes_root"]
    if cfg["bikes"] == "all":
        if not os.path.isdir(root):
            raise _err("bikes_root", f"no such folder {root!r}")
        bikes = sorted(d for d in os.listdir(root) if os.path.isfile(os.path.join(root, d, "keypoints.json")))
        if cfg["mode"] in ("cyclist", "street", "frames"):  # a rider needs pedals and a seat
            bikes = [b for b in bikes if bike_folder.has_crank(os.path.join(root, b))]
        if not bikes:
            raise _err("bikes", f"'all' found no bike folders with keypoints.json under {root!r}")
        cfg["bikes"] = bikes
    else:
        for b in cfg["bikes"]:
            d = b if os.path.isdir(b) else os.path.join(root, b)
            if not os.path.isfile(os.path.join(d, "keypoints.json")):
                raise _err("bikes", f"{b!r} is not a bike folder (no {os.path.join(d, 'keypoints.json')})")
    lighting.check_assets(cfg)
    return cfg


def load_config(path=None, preset=None, overrides=None, nested=None):
    """Config from a YAML file or a preset name (not both), with CLI overrides {field: value} and
    nested ones {section: {field: value}} merged into the file's sections."""
    if (path is None) == (preset is None):
        raise UserError("give exactly one of --config FILE or --preset NAME")
    raw = load_yaml(path if path else preset_path(preset))
    if not isinstance(raw, dict):
        raise _err("<top>", f"expected a mapping of fields, got {type(raw).__name__}")
    for k, v in (overrides or {}).items():
        if v is not None:
            raw[k] = v
    for sec, fields in (nested or {}).items():
        if not isinstance(raw.get(sec, {}), dict):
            raise _err(sec, "expected a mapping")
        raw[sec] = dict(raw.get(sec) or {}, **fields)
    return validate(raw)

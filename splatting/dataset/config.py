"""Dataset configuration: YAML -> a validated DatasetConfig (defaults filled in), assets resolved.

The fields, their defaults and ranges are the models of splatting/dataset/config_models.py; every
error names the field it is about in one line: `config field 'views.azimuth_deg': expected
[min, max] ...`.  Unknown fields are errors too (a typo would otherwise silently fall back to a
default).  The generator takes the model itself and reads its attributes; a plain mapping becomes a
model here (validate, load_config, from_record) and nowhere else.  The resolved config (asset lists
expanded) is stored beside the dataset as generate.config_record(cfg); a resumed run must resolve to
the same record.
"""
import os

from cyclist_formats import bike_folder, typed_config
from cyclist_formats.errors import UserError
from cyclist_formats.text_files import read_yaml
from splatting import paths
from splatting.cyclist import accessories
from splatting.dataset import lighting
from splatting.dataset.backgrounds import list_images
from splatting.dataset.config_models import DatasetConfig, require_config
from splatting.rider.roster import all_riders

PRESET_DIR = str(paths.BLEND_ASSETS / "datasets")
DEFAULTS = DatasetConfig().model_dump()  # {field: default}, a mapping to build raw configs from (tests)


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
    """Raw mapping (from YAML) -> DatasetConfig, checked field by field; values as written."""
    return typed_config.validate(DatasetConfig, raw)


def from_record(record, what="dataset config record"):
    """The config.json stored beside a dataset (generate.config_record) -> DatasetConfig: the sections a
    record leaves out (baked lighting, frames fields outside frames mode, disabled sequences) are
    their defaults, which is what they were.  A resolved bike-only record holds `riders: []`
    (resolve_assets), which a config may not say: it is checked as the default, then set back."""
    no_riders = record.get("riders") == []
    raw = {k: v for k, v in record.items() if not (no_riders and k == "riders")}
    cfg = typed_config.validate(DatasetConfig, raw, what=f"{what} field")
    return cfg.model_copy(update={"riders": []}) if no_riders else cfg


def resolve_assets(cfg):
    """DatasetConfig -> a copy with 'all' expanded and every rider and bike checked (config field
    named on failure); the frames folder located and read, photo backgrounds listed."""
    require_config(cfg, "resolve_assets")
    update = {}
    if cfg.mode == "frames":
        from splatting.dataset.frames.source import locate, open_folder
        update["frames"] = locate(cfg.frames)
        open_folder(update["frames"])  # every frame's calib, labels, plane and scan size, before any work
    if cfg.mode in ("cyclist", "street", "frames"):
        known = [r["id"] for r in all_riders()]
        riders = known if cfg.riders == "all" else cfg.riders
        bad = [r for r in riders if r not in known]
        if bad:
            raise _err("riders", f"unknown rider ids {bad} (known: {', '.join(known)})")
        update["riders"] = list(riders)
    else:
        update["riders"] = []
    b = cfg.backgrounds
    if "images" in b.kinds and b.image_files is None:
        update["backgrounds"] = b.model_copy(update={"image_files": [os.path.abspath(f) for f in list_images(b.images_dir)]})
    if "scene" in b.kinds and not os.path.isfile(b.scene_ply):
        raise _err("backgrounds.scene_ply", f"no such file {b.scene_ply!r}")
    root = cfg.bikes_root
    if cfg.bikes == "all":
        if not os.path.isdir(root):
            raise _err("bikes_root", f"no such folder {root!r}")
        bikes = sorted(d for d in os.listdir(root) if os.path.isfile(os.path.join(root, d, "keypoints.json")))
        if cfg.mode in ("cyclist", "street", "frames"):  # a rider needs pedals and a seat
            bikes = [b for b in bikes if bike_folder.has_crank(os.path.join(root, b))]
        if not bikes:
            raise _err("bikes", f"'all' found no bike folders with keypoints.json under {root!r}")
        update["bikes"] = bikes
    else:
        for b in cfg.bikes:
            d = b if os.path.isdir(b) else os.path.join(root, b)
            if not os.path.isfile(os.path.join(d, "keypoints.json")):
                raise _err("bikes", f"{b!r} is not a bike folder (no {os.path.join(d, 'keypoints.json')})")
        update["bikes"] = list(cfg.bikes)
    cfg = cfg.model_copy(update=update)
    lighting.check_assets(cfg)
    accessories.check(cfg)
    return cfg


def load_config(path=None, preset=None, overrides=None, nested=None):
    """DatasetConfig from a YAML file or a preset name (not both), with CLI overrides {field: value}
    and nested ones {section: {field: value}} merged into the file's sections."""
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

"""Dataset configuration: YAML -> a validated, fully resolved dict (defaults filled in).

Every error names the field it is about: `config field 'views.azimuth_deg': expected [min, max]`.
Unknown fields are errors too (a typo would otherwise silently fall back to a default).
The resolved config (asset lists expanded) is stored beside the dataset; a resumed run must
resolve to the same one.
"""
import copy
import os

import yaml

from cyclist_formats.errors import UserError
from splatting import paths

PRESET_DIR = str(paths.BLEND_ASSETS / "datasets")
MODES = ("cyclist", "bike-only")
BACKGROUNDS = ("solid", "gradient", "noise")
from cyclist_formats.pose import POSE_FIELDS as POSE_KEYS  # config keys are the contract's field names

DEFAULTS = {
    "name": "dataset",
    "mode": "cyclist",
    "seed": 0,
    "count": 100,
    "image_size": 512,
    "riders": ["m_adult_average_185"],
    "riders_root": "data/riders",
    "bikes": "all",
    "bikes_root": "out/bikes",
    "synthetic_assets": "auto",          # auto: trained Gaussians where they exist, else stand-ins
    "synthetic_gaussians_per_part": 3000,
    "rider_gaussians": None,             # subsample an untrained (mesh) avatar; null = every vertex
    "ik_iterations": 50,
    "pose": {"theta_p_deg": [0, 360], "theta_s_deg": [-30, 30], "theta_x_deg": [-5, 5],
             "theta_y_deg": [-180, 180], "theta_z_deg": [-5, 5],
             "t_x_m": [0, 0], "t_y_m": [0, 0], "t_z_m": [0, 0]},
    "views": {"azimuth_deg": [-180, 180], "elevation_deg": [0, 25], "distance_m": [10, 14],
              "focal_px": None, "centre_jitter_m": 0.1},
    "backgrounds": {"kinds": ["solid", "gradient", "noise"]},
    "keypoints": {"person": "smpl24", "tolerance_bike_m": 0.08, "tolerance_rider_m": 0.15},
    "png_compress_level": 4,
}


def _err(field, msg):
    return UserError(f"config field '{field}': {msg}")


def _num(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool) and v == v and abs(v) != float("inf")


def _range(cfg, field, lo=None, hi=None):
    v = cfg
    for k in field.split("."):
        v = v[k]
    if not (isinstance(v, list) and len(v) == 2 and all(_num(x) for x in v) and v[0] <= v[1]):
        raise _err(field, f"expected [min, max] with min <= max, got {v!r}")
    if (lo is not None and v[0] < lo) or (hi is not None and v[1] > hi):
        raise _err(field, f"expected values within [{lo}, {hi}], got {v!r}")
    return [float(x) for x in v]


def _merge(base, over, prefix=""):
    out = copy.deepcopy(base)
    if not isinstance(over, dict):
        raise _err(prefix.rstrip(".") or "<top>", f"expected a mapping, got {type(over).__name__}")
    for k, v in over.items():
        field = prefix + str(k)
        if k not in base:
            raise _err(field, f"unknown field (known: {', '.join(base)})")
        if isinstance(base[k], dict):
            out[k] = _merge(base[k], v, field + ".")
        else:
            out[k] = v
    return out


def load_yaml(path):
    try:
        with open(path) as f:
            data = yaml.safe_load(f)
    except FileNotFoundError:
        raise UserError(f"no such config file: {path}")
    except yaml.YAMLError as e:
        raise UserError(f"{path} is not valid YAML: {str(e).splitlines()[0]}")
    return {} if data is None else data


def preset_path(name):
    p = os.path.join(PRESET_DIR, f"{name}.yaml")
    if not os.path.isfile(p):
        known = sorted(f[:-5] for f in os.listdir(PRESET_DIR) if f.endswith(".yaml")) if os.path.isdir(PRESET_DIR) else []
        raise UserError(f"unknown preset {name!r} (known: {', '.join(known)})")
    return p


def validate(raw):
    """Raw mapping (from YAML) -> config with defaults, checked field by field."""
    cfg = _merge(DEFAULTS, raw)
    if cfg["mode"] not in MODES:
        raise _err("mode", f"expected one of {', '.join(MODES)}, got {cfg['mode']!r}")
    for f, lo in (("seed", 0), ("count", 1), ("image_size", 16), ("synthetic_gaussians_per_part", 10),
                  ("ik_iterations", 1)):
        if not isinstance(cfg[f], int) or isinstance(cfg[f], bool) or cfg[f] < lo:
            raise _err(f, f"expected an integer >= {lo}, got {cfg[f]!r}")
    if cfg["rider_gaussians"] is not None and (not isinstance(cfg["rider_gaussians"], int) or cfg["rider_gaussians"] < 100):
        raise _err("rider_gaussians", f"expected null or an integer >= 100, got {cfg['rider_gaussians']!r}")
    if not isinstance(cfg["png_compress_level"], int) or not 0 <= cfg["png_compress_level"] <= 9:
        raise _err("png_compress_level", f"expected an integer 0..9, got {cfg['png_compress_level']!r}")
    if cfg["synthetic_assets"] not in ("auto", "always", "never"):
        raise _err("synthetic_assets", f"expected auto, always or never, got {cfg['synthetic_assets']!r}")
    if not isinstance(cfg["name"], str) or not cfg["name"]:
        raise _err("name", "expected a non-empty string")
    for f in ("riders", "bikes"):
        v = cfg[f]
        if not (v == "all" or (isinstance(v, list) and v and all(isinstance(x, str) and x for x in v))):
            raise _err(f, f"expected 'all' or a non-empty list of ids, got {v!r}")
    for f in ("riders_root", "bikes_root"):
        if not isinstance(cfg[f], str):
            raise _err(f, "expected a folder path")
    for k in POSE_KEYS:
        _range(cfg, f"pose.{k}")
    _range(cfg, "views.azimuth_deg")
    _range(cfg, "views.elevation_deg", -89, 89)
    _range(cfg, "views.distance_m", 0.5, None)
    fp = cfg["views"]["focal_px"]
    if fp is not None and not (_num(fp) and fp > 0):
        raise _err("views.focal_px", f"expected null or a positive number, got {fp!r}")
    if not (_num(cfg["views"]["centre_jitter_m"]) and cfg["views"]["centre_jitter_m"] >= 0):
        raise _err("views.centre_jitter_m", "expected a number >= 0")
    kinds = cfg["backgrounds"]["kinds"]
    if not (isinstance(kinds, list) and kinds and all(k in BACKGROUNDS for k in kinds)):
        raise _err("backgrounds.kinds", f"expected a non-empty list of {', '.join(BACKGROUNDS)}, got {kinds!r}")
    if cfg["keypoints"]["person"] != "smpl24":
        raise _err("keypoints.person", f"only 'smpl24' is implemented, got {cfg['keypoints']['person']!r}")
    for f in ("tolerance_bike_m", "tolerance_rider_m"):
        if not (_num(cfg["keypoints"][f]) and cfg["keypoints"][f] >= 0):
            raise _err(f"keypoints.{f}", "expected a number >= 0")
    return cfg


def resolve_assets(cfg):
    """Expand 'all' and check that every rider and bike exists (config field named on failure)."""
    from splatting.rider.roster import load_roster
    cfg = copy.deepcopy(cfg)
    if cfg["mode"] == "cyclist":
        known = [r["id"] for r in load_roster()]
        riders = known if cfg["riders"] == "all" else cfg["riders"]
        bad = [r for r in riders if r not in known]
        if bad:
            raise _err("riders", f"unknown rider ids {bad} (known: {', '.join(known)})")
        cfg["riders"] = list(riders)
    else:
        cfg["riders"] = []
    root = cfg["bikes_root"]
    if cfg["bikes"] == "all":
        if not os.path.isdir(root):
            raise _err("bikes_root", f"no such folder {root!r}")
        bikes = sorted(d for d in os.listdir(root) if os.path.isfile(os.path.join(root, d, "keypoints.json")))
        if cfg["mode"] == "cyclist":  # a rider needs pedals and a seat
            bikes = [b for b in bikes if _has_crank(os.path.join(root, b))]
        if not bikes:
            raise _err("bikes", f"'all' found no bike folders with keypoints.json under {root!r}")
        cfg["bikes"] = bikes
    else:
        for b in cfg["bikes"]:
            d = b if os.path.isdir(b) else os.path.join(root, b)
            if not os.path.isfile(os.path.join(d, "keypoints.json")):
                raise _err("bikes", f"{b!r} is not a bike folder (no {os.path.join(d, 'keypoints.json')})")
    return cfg


def _has_crank(d):
    import json
    try:
        with open(os.path.join(d, "meta.json")) as f:
            return bool(json.load(f).get("has_crank", True))
    except (OSError, ValueError):
        return False


def load_config(path=None, preset=None, overrides=None):
    """Config from a YAML file or a preset name (not both), with CLI overrides {field: value}."""
    if (path is None) == (preset is None):
        raise UserError("give exactly one of --config FILE or --preset NAME")
    raw = load_yaml(path if path else preset_path(preset))
    if not isinstance(raw, dict):
        raise _err("<top>", f"expected a mapping of fields, got {type(raw).__name__}")
    for k, v in (overrides or {}).items():
        if v is not None:
            raw[k] = v
    return validate(raw)

"""Dataset configuration: YAML -> a validated, fully resolved dict (defaults filled in).

Every error names the field it is about: `config field 'views.azimuth_deg': expected [min, max]`.
Unknown fields are errors too (a typo would otherwise silently fall back to a default).
The resolved config (asset lists expanded) is stored beside the dataset; a resumed run must
resolve to the same one.
"""
import copy
import os

from cyclist_formats import bike_folder, checks
from cyclist_formats.errors import UserError
from cyclist_formats.text_files import read_yaml
from splatting import paths

PRESET_DIR = str(paths.BLEND_ASSETS / "datasets")
MODES = ("cyclist", "bike-only", "street", "frames")
BACKGROUNDS = ("solid", "gradient", "noise", "images", "scene")
PERSON_KEYPOINTS = ("coco17", "smpl24")
LABEL_FORMATS = ("coco", "kitti", "mot")  # mot: sequences only
from cyclist_formats.pose import POSE_FIELDS as POSE_KEYS  # config keys are the contract's field names
from splatting.dataset.camera_presets import DEFAULTS as CAMERA_DEFAULTS
from splatting.cyclist.appearance import RECOLOUR
from splatting.cyclist.lod import DEFAULT_COMPENSATE as LOD_COMPENSATE, DEFAULT_LEVELS as LOD_LEVELS
from splatting.dataset.labels import DEFAULT_COMBINED, DEFAULT_NAMES, VEHICLES
from splatting.dataset import camera_presets, lighting
from splatting.dataset.backgrounds import list_images
from splatting.dataset.sequences.trajectory import MANOEUVRES
from splatting.rider.roster import all_riders

INSERT_DEFAULTS = {
    "lidar": True,                # use velodyne/ when present: plane fallback, road checks, occlusion, scan output
    "box_margin_m": 0.5,          # kept clear around every labelled 3D box's footprint
    "min_ground_points": 3,       # LiDAR road points around a footprint for it to count as seen road
    "camera_height_m": 1.65,      # the level road below camera 0 when a frame has neither planes nor LiDAR
    "occlusion_margin_m": 0.3,    # the frame hides an inserted pixel only when nearer by more than this
    "behind_cars_share": 0.0,     # share of instances sought just beyond a labelled car (partly hidden by it)
    "box_occluders": True,        # the labelled 3D boxes, drawn solid, hide what is behind them
    "look": {"match": True, "blur_sigma_px": "auto", "noise_sigma": "auto", "sun_elevation_deg": 45.0,
             "sun_azimuth_deg": 120.0, "cast_shadow": True},
}

SEQUENCE_DEFAULTS = {
    "enabled": False,
    "length": 100,                # frames per sequence
    "fps": 10.0,                  # KITTI's rate
    "manoeuvres": {m: 1.0 for m in MANOEUVRES},  # relative weights (0 = never)
    "speed_mps": [2.0, 8.0],
    "turn_radius_m": [6.0, 20.0],  # tightest radius of a turn (raised above v^2 / max_lateral_accel)
    "max_lateral_accel_mps2": 3.0,
    "cadence_rpm": [60.0, 90.0],  # cruising cadence; sets each cyclist's gear ratio
    "lane_half_width_m": 1.5,     # the ego's lane about its path X = 0 (the crossing label)
    "ego": {"motion": "moving", "speed_mps": [4.0, 10.0]},  # moving | static
    "signal_share": 0.6,          # share of turns, crossings and stops announced by an arm signal
    "signal_lead_s": [1.0, 3.0],  # the signal shows from this long before the turn / braking until it starts
    "one_handed_share": 0.2,      # share of `straight` riders riding one-handed for a while
    "exposure_s": 0.0,            # motion blur: shutter time (0 = off: the instant's image)
    "blur_subframes": 5,          # renders averaged over the exposure (odd: the middle one is the frame's instant)
    "still_signal_share": 0.0,    # still sets (sequence.enabled false): share of riders showing an arm signal
}

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
    "camera": dict(CAMERA_DEFAULTS),
    "street": {"cyclists": [1, 6], "parked_bikes": [0, 1], "distance_m": [3, 60], "lateral_m": [-15, 15],
               "border_margin": 0.1, "heading": "road", "road_heading_deg": 0.0, "heading_spread_deg": 15.0,
               "oncoming_share": 0.4, "footprint_radius_m": 1.0, "max_tries": 50, "parked_steer_deg": [-40, 40]},
    "backgrounds": {"kinds": ["solid", "gradient", "noise"], "images_dir": None, "image_files": None,
                    "scene_ply": None,
                    "scene_transform": {"rotation_deg": [0, 0, 0], "translation_m": [0, 0, 0], "scale": 1.0},
                    "shadow": True, "shadow_opacity": 0.55},
    "keypoints": {"person": "coco17", "tolerance_bike_m": 0.08, "tolerance_rider_m": 0.15},
    "labels": {"formats": ["coco"], "names": dict(DEFAULT_NAMES), "combined": dict(DEFAULT_COMBINED),
               "vehicle_of": {}},
    "depth_maps": False,
    "amodal_max_px": None,               # amodal masks of larger parts at reduced resolution (speed)
    "png_compress_level": 4,
    # level of detail (splatting/cyclist/lod.py): instances shorter than a level's below_px on
    # screen are rendered with `keep` of their Gaussians; off by default, on in the street preset
    "lod": {"enabled": False, "levels": copy.deepcopy(LOD_LEVELS), "compensate": LOD_COMPENSATE},
    # appearance variety (splatting/cyclist/appearance.py): per instance, new colours for the listed
    # regions (HSV: any hue, saturation and value in the ranges; each region kept as trained with
    # keep_share) and a gain: brightness x white balance (+-white_balance per channel)
    "appearance": {"enabled": False, "regions": list(RECOLOUR), "keep_share": 0.25, "saturation": [0.15, 0.9],
                   "value": [0.12, 0.95], "brightness": [0.75, 1.25], "white_balance": 0.08},
    # per-image light (splatting/dataset/lighting.py): baked = the trained colour; relit = a sun and
    # sky drawn per image from these ranges, bikes and riders shaded from their relight channels
    "lighting": copy.deepcopy(lighting.DEFAULTS),
    # frames mode (docs/kitti_insert.md): cyclists inserted into the frames of a KITTI object folder;
    # counts, distances and headings come from `street`, the rest from `insert`
    "frames": None,
    "insert": copy.deepcopy(INSERT_DEFAULTS),
    # street sequences (docs/sequences.md): `count` counts sequences of `length` frames
    "sequence": copy.deepcopy(SEQUENCE_DEFAULTS),
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


FREE_MAPPINGS = ("labels.vehicle_of",)  # mappings whose keys are the user's (bike ids)


def _merge(base, over, prefix=""):
    out = copy.deepcopy(base)
    if not isinstance(over, dict):
        raise _err(prefix.rstrip(".") or "<top>", f"expected a mapping, got {type(over).__name__}")
    for k, v in over.items():
        field = prefix + str(k)
        if k not in base:
            raise _err(field, f"unknown field (known: {', '.join(base) or 'none'})")
        if field in FREE_MAPPINGS:
            if not isinstance(v, dict):
                raise _err(field, f"expected a mapping, got {type(v).__name__}")
            out[k] = dict(v)
        elif isinstance(base[k], dict):
            out[k] = _merge(base[k], v, field + ".")
        else:
            out[k] = v
    return out


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
    if not checks.SAFE_NAME.match(cfg["name"]):  # it names the default output folder out/datasets/<name>
        raise _err("name", f"expected a name of letters, digits, '.', '_' or '-' (starting with a letter or digit, "
                           f"at most 100), got {cfg['name']!r}")
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
    _validate_street(cfg)
    if cfg["keypoints"]["person"] not in PERSON_KEYPOINTS:
        raise _err("keypoints.person", f"expected one of {', '.join(PERSON_KEYPOINTS)}, got {cfg['keypoints']['person']!r}")
    for f in ("tolerance_bike_m", "tolerance_rider_m"):
        if not (_num(cfg["keypoints"][f]) and cfg["keypoints"][f] >= 0):
            raise _err(f"keypoints.{f}", "expected a number >= 0")
    return cfg


def _validate_street(cfg):
    cam = camera_presets.resolve(cfg["camera"])
    if cfg["mode"] == "street" and cam is None:
        raise _err("camera.preset", "street mode needs a driving camera (kitti, nuscenes, waymo, dashcam, custom)")
    if cfg["mode"] != "street" and cam is not None:
        raise _err("camera.preset", f"{cfg['mode']} mode uses the ring camera (set mode: street for driving cameras)")
    st = cfg["street"]
    for f, lo in (("cyclists", 0), ("parked_bikes", 0)):
        v = st[f]
        if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, int) and not isinstance(x, bool) for x in v)
                and lo <= v[0] <= v[1] <= 64):
            raise _err(f"street.{f}", f"expected [min, max] integers within 0..64, got {v!r}")
    _range(cfg, "street.distance_m", 0.5, None)
    _range(cfg, "street.lateral_m")
    _range(cfg, "street.parked_steer_deg", -90, 90)
    for f, lo, hi in (("border_margin", 0, 1), ("road_heading_deg", -360, 360), ("heading_spread_deg", 0, 180),
                      ("oncoming_share", 0, 1), ("footprint_radius_m", 0.05, 10)):
        if not (_num(st[f]) and lo <= st[f] <= hi):
            raise _err(f"street.{f}", f"expected a number within [{lo}, {hi}], got {st[f]!r}")
    if not isinstance(st["max_tries"], int) or st["max_tries"] < 1:
        raise _err("street.max_tries", f"expected an integer >= 1, got {st['max_tries']!r}")
    if st["heading"] not in ("road", "uniform"):
        raise _err("street.heading", f"expected road or uniform, got {st['heading']!r}")
    b = cfg["backgrounds"]
    if "images" in b["kinds"] and not (isinstance(b["images_dir"], str) or isinstance(b["image_files"], list)):
        raise _err("backgrounds.images_dir", "the 'images' background needs a folder of JPG/PNG files")
    if "scene" in b["kinds"] and not isinstance(b["scene_ply"], str):
        raise _err("backgrounds.scene_ply", "the 'scene' background needs a 3DGS .ply (INRIA layout)")
    t = b["scene_transform"]
    for f in ("rotation_deg", "translation_m"):
        if not (isinstance(t[f], list) and len(t[f]) == 3 and all(_num(x) for x in t[f])):
            raise _err(f"backgrounds.scene_transform.{f}", f"expected [x, y, z], got {t[f]!r}")
    if not (_num(t["scale"]) and t["scale"] > 0):
        raise _err("backgrounds.scene_transform.scale", f"expected a positive number, got {t['scale']!r}")
    if not isinstance(b["shadow"], bool):
        raise _err("backgrounds.shadow", f"expected true or false, got {b['shadow']!r}")
    if not (_num(b["shadow_opacity"]) and 0 <= b["shadow_opacity"] <= 0.99):
        raise _err("backgrounds.shadow_opacity", f"expected a number within [0, 0.99], got {b['shadow_opacity']!r}")
    lab = cfg["labels"]
    fm = lab["formats"]
    if not (isinstance(fm, list) and fm and all(f in LABEL_FORMATS for f in fm)):
        raise _err("labels.formats", f"expected a non-empty list of {', '.join(LABEL_FORMATS)}, got {fm!r}")
    for k, v in lab["names"].items():
        if not (isinstance(v, str) and v):
            raise _err(f"labels.names.{k}", f"expected a non-empty name, got {v!r}")
    if len(set(lab["names"].values())) != len(lab["names"]):
        raise _err("labels.names", "category names must differ")
    for k, v in lab["combined"].items():
        if v not in ("cyclist", "motorcyclist"):
            raise _err(f"labels.combined.{k}", f"expected cyclist or motorcyclist, got {v!r}")
    for k, v in lab["vehicle_of"].items():
        if v not in VEHICLES:
            raise _err(f"labels.vehicle_of.{k}", f"expected one of {', '.join(VEHICLES)}, got {v!r}")
    a = cfg["amodal_max_px"]
    if a is not None and (not isinstance(a, int) or isinstance(a, bool) or a < 32):
        raise _err("amodal_max_px", f"expected null or an integer >= 32, got {a!r}")
    if not isinstance(cfg["depth_maps"], bool):
        raise _err("depth_maps", f"expected true or false, got {cfg['depth_maps']!r}")
    _validate_lod(cfg["lod"])
    _validate_appearance(cfg["appearance"])
    lighting.validate(cfg["lighting"])
    _validate_insert(cfg)
    _validate_sequence(cfg)


def _validate_sequence(cfg):
    sq = cfg["sequence"]
    if not isinstance(sq["enabled"], bool):
        raise _err("sequence.enabled", f"expected true or false, got {sq['enabled']!r}")
    if not (_num(sq["still_signal_share"]) and 0 <= sq["still_signal_share"] <= 1):
        raise _err("sequence.still_signal_share", f"expected a number within [0, 1], got {sq['still_signal_share']!r}")
    if not sq["enabled"]:
        if "mot" in cfg["labels"]["formats"]:
            raise _err("labels.formats", "mot (MOTChallenge) is a tracking format: it needs sequence.enabled: true")
        return
    if cfg["mode"] != "street":
        raise _err("sequence.enabled", f"sequences are street scenes (mode: street), got mode {cfg['mode']!r}")
    if cfg["lighting"]["mode"] != "baked":
        raise _err("lighting.mode", "sequences use the baked light (a relit sun per frame would flicker)")
    n = sq["length"]
    if not isinstance(n, int) or isinstance(n, bool) or not 2 <= n <= 100000:
        raise _err("sequence.length", f"expected an integer within 2..100000, got {n!r}")
    if not (_num(sq["fps"]) and 0.5 <= sq["fps"] <= 240):
        raise _err("sequence.fps", f"expected a number within [0.5, 240], got {sq['fps']!r}")
    w = sq["manoeuvres"]
    if not all(_num(v) and v >= 0 for v in w.values()) or not sum(w.values()) > 0:
        raise _err("sequence.manoeuvres", f"expected weights >= 0, not all 0, got {w!r}")
    _range(cfg, "sequence.speed_mps", 0.5, 15)
    _range(cfg, "sequence.turn_radius_m", 2, 200)
    _range(cfg, "sequence.cadence_rpm", 20, 150)
    _range(cfg, "sequence.ego.speed_mps", 0, 40)
    for f, lo, hi in (("max_lateral_accel_mps2", 0.5, 9.81), ("lane_half_width_m", 0.5, 10)):
        if not (_num(sq[f]) and lo <= sq[f] <= hi):
            raise _err(f"sequence.{f}", f"expected a number within [{lo}, {hi}], got {sq[f]!r}")
    for f, lo, hi in (("signal_share", 0, 1), ("one_handed_share", 0, 1), ("exposure_s", 0, 1)):
        if not (_num(sq[f]) and lo <= sq[f] <= hi):
            raise _err(f"sequence.{f}", f"expected a number within [{lo}, {hi}], got {sq[f]!r}")
    if sq["exposure_s"] > 1.0 / sq["fps"]:
        raise _err("sequence.exposure_s", f"the shutter cannot stay open longer than a frame (1 / fps = "
                   f"{1.0 / sq['fps']:.4g} s), got {sq['exposure_s']!r}")
    _range(cfg, "sequence.signal_lead_s", 0, 30)
    k = sq["blur_subframes"]
    if not (isinstance(k, int) and not isinstance(k, bool) and 1 <= k <= 99 and k % 2 == 1):
        raise _err("sequence.blur_subframes", f"expected an odd integer within 1..99, got {k!r}")
    if sq["ego"]["motion"] not in ("moving", "static"):
        raise _err("sequence.ego.motion", f"expected moving or static, got {sq['ego']['motion']!r}")


def _validate_insert(cfg):
    ins = cfg["insert"]
    if cfg["mode"] == "frames" and not (isinstance(cfg["frames"], str) and cfg["frames"]):
        raise _err("frames", f"frames mode needs a KITTI object folder (or --frames DIR), got {cfg['frames']!r}")
    for f in ("lidar", "box_occluders"):
        if not isinstance(ins[f], bool):
            raise _err(f"insert.{f}", f"expected true or false, got {ins[f]!r}")
    for f, lo, hi in (("box_margin_m", 0, 10), ("camera_height_m", 0.2, 10), ("occlusion_margin_m", 0, 5),
                      ("behind_cars_share", 0, 1)):
        if not (_num(ins[f]) and lo <= ins[f] <= hi):
            raise _err(f"insert.{f}", f"expected a number within [{lo}, {hi}], got {ins[f]!r}")
    if not (isinstance(ins["min_ground_points"], int) and not isinstance(ins["min_ground_points"], bool)
            and ins["min_ground_points"] >= 0):
        raise _err("insert.min_ground_points", f"expected an integer >= 0, got {ins['min_ground_points']!r}")
    lk = ins["look"]
    for f in ("match", "cast_shadow"):
        if not isinstance(lk[f], bool):
            raise _err(f"insert.look.{f}", f"expected true or false, got {lk[f]!r}")
    for f, lo, hi in (("blur_sigma_px", 0, 5), ("noise_sigma", 0, 0.2)):
        if lk[f] != "auto" and not (_num(lk[f]) and lo <= lk[f] <= hi):
            raise _err(f"insert.look.{f}", f"expected auto or a number within [{lo}, {hi}], got {lk[f]!r}")
    if not (_num(lk["sun_azimuth_deg"]) and -360 <= lk["sun_azimuth_deg"] <= 360):
        raise _err("insert.look.sun_azimuth_deg", f"expected a number within [-360, 360], got {lk['sun_azimuth_deg']!r}")
    if not (_num(lk["sun_elevation_deg"]) and 1 <= lk["sun_elevation_deg"] <= 90):
        raise _err("insert.look.sun_elevation_deg", f"expected a number within [1, 90], got {lk['sun_elevation_deg']!r}")


def _validate_appearance(a):
    if not isinstance(a["enabled"], bool):
        raise _err("appearance.enabled", f"expected true or false, got {a['enabled']!r}")
    r = a["regions"]
    if not (isinstance(r, list) and all(x in RECOLOUR for x in r)):
        raise _err("appearance.regions", f"expected a list of {', '.join(RECOLOUR)}, got {r!r}")
    for f, lo, hi in (("keep_share", 0, 1), ("white_balance", 0, 0.5)):
        if not (_num(a[f]) and lo <= a[f] <= hi):
            raise _err(f"appearance.{f}", f"expected a number within [{lo}, {hi}], got {a[f]!r}")
    cfg = {"appearance": a}
    _range(cfg, "appearance.saturation", 0, 1)
    _range(cfg, "appearance.value", 0, 1)
    _range(cfg, "appearance.brightness", 0.05, 4)


def _validate_lod(lod):
    if not isinstance(lod["enabled"], bool):
        raise _err("lod.enabled", f"expected true or false, got {lod['enabled']!r}")
    if not (_num(lod["compensate"]) and 0 <= lod["compensate"] <= 2):
        raise _err("lod.compensate", f"expected a number within [0, 2], got {lod['compensate']!r}")
    lv = lod["levels"]
    if not isinstance(lv, list):
        raise _err("lod.levels", f"expected a list of {{below_px, keep}}, got {lv!r}")
    for i, x in enumerate(lv):
        if not (isinstance(x, dict) and set(x) == {"below_px", "keep"}):
            raise _err(f"lod.levels[{i}]", f"expected {{below_px: PIXELS, keep: SHARE}}, got {x!r}")
        if not (_num(x["below_px"]) and x["below_px"] > 0):
            raise _err(f"lod.levels[{i}].below_px", f"expected a positive number, got {x['below_px']!r}")
        if not (_num(x["keep"]) and 0 < x["keep"] <= 1):
            raise _err(f"lod.levels[{i}].keep", f"expected a share within (0, 1], got {x['keep']!r}")
    by_h = sorted(lv, key=lambda x: -x["below_px"])
    if any(b["keep"] > a["keep"] for a, b in zip(by_h, by_h[1:])):
        raise _err("lod.levels", "a level for shorter instances must not keep more Gaussians")


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

"""The dataset config as typed models: one model per block, defaults and ranges in the declarations.

This is the one place the config's fields, defaults and limits are written (docs/cyclists_and_datasets.md
lists them).  `splatting.dataset.config.load_config` validates a YAML file against DatasetConfig and
the generator receives that DatasetConfig (and reads `cfg.street.distance_m`, never a dict).  Values
keep the type they were written with, so `generate.config_record(cfg)` -- the one place the model
becomes a dict again -- stores the config.json beside a dataset with its bytes unchanged.  Checks that
span several fields (a street camera for street mode, distinct category names...) are in
DatasetConfig's model validator.

Adding a block: write a `class MyBlock(Block)` with its fields, then one field
`my_block: MyBlock = Field(default_factory=MyBlock, description=...)` in DatasetConfig; a new block
that older datasets lack is left out of their config record in generate.config_record.

Torch-free on purpose: the dataset command builds its flags from DatasetConfig at `--help` time.
"""
import math
from typing import Annotated, Literal, Optional, Union

from pydantic import PlainValidator, model_validator
from pydantic_core import PydanticCustomError

from cyclist_formats import checks
from cyclist_formats.typed_config import (AutoOr, Block, Bool, Field, Int, IntRange, Number, Range, Str, Vec3,
                                          defaults_of, field_error)
from splatting.cyclist.look_defaults import DEFAULT_COMPENSATE, DEFAULT_LEVELS, HAIR_STYLES, RECOLOUR, RECOLOUR_EXTRA
from splatting.dataset.sequences.trajectory import MANOEUVRES

# ------------------------------------------------------------------ camera

RING = "ring"
# Driving cameras (values as the datasets publish them; splatting/dataset/camera_presets.py):
# - kitti: KITTI object benchmark, left colour camera P2 of the 2011_09_26 calibration; 1.65 m.
# - nuscenes: CAM_FRONT, ~1.51 m.  waymo: FRONT, ~2.1 m.  dashcam: 1920x1080, 90 deg hfov, 1.3 m.
CAMERA_PRESETS = {
    "kitti": {"width": 1242, "height": 375, "fx": 721.5377, "fy": 721.5377, "cx": 609.5593, "cy": 172.854,
              "height_m": 1.65},
    "nuscenes": {"width": 1600, "height": 900, "fx": 1266.4, "fy": 1266.4, "cx": 816.3, "cy": 491.5,
                 "height_m": 1.51},
    "waymo": {"width": 1920, "height": 1280, "fx": 2055.6, "fy": 2055.6, "cx": 939.7, "cy": 641.1,
              "height_m": 2.1},
    "dashcam": {"width": 1920, "height": 1080, "hfov_deg": 90.0, "height_m": 1.3},
}
CameraPreset = Literal["ring", "kitti", "nuscenes", "waymo", "dashcam", "custom"]

Positive = Annotated[Number, Field(gt=0)]


class Camera(Block):
    """`camera`: the ring (object-centred, size from image_size) or a driving camera; a preset's
    fields can be overridden one by one, `custom` takes them all from here."""
    preset: CameraPreset = RING
    width: Optional[Annotated[Int, Field(ge=16)]] = None
    height: Optional[Annotated[Int, Field(ge=16)]] = None
    fx: Optional[Positive] = None
    fy: Optional[Positive] = None
    cx: Optional[Number] = None
    cy: Optional[Number] = None
    hfov_deg: Optional[Annotated[Number, Field(ge=1, le=170)]] = None
    height_m: Optional[Positive] = None
    pitch_deg: Annotated[Number, Field(ge=-60, le=60, description="positive = nose down")] = 0.0
    roll_deg: Annotated[Number, Field(ge=-45, le=45)] = 0.0
    scale: Annotated[Number, Field(ge=0.05, le=4, description="render at this fraction of the resolution")] = 1.0


CAMERA_NAMES = (RING, *CAMERA_PRESETS, "custom")
CAMERA_DEFAULTS = defaults_of(Camera)


def resolve_camera(camera):
    """The config's Camera block -> a complete driving-camera spec (a dict: width, height, fx, fy,
    cx, cy, height_m, pitch_deg, roll_deg, preset), or None for the ring.  The rules across the
    camera's fields are here; errors name the field."""
    def err(field, msg):
        return field_error(f"camera.{field}", msg)
    fields = tuple(CAMERA_DEFAULTS)[1:]
    name = camera.preset
    given = {k: getattr(camera, k) for k in fields}
    if name == RING:
        extra = [k for k in fields if given[k] is not None and given[k] != CAMERA_DEFAULTS[k]]
        if extra:
            raise err(extra[0], "the ring camera takes its size from image_size and its view from 'views'; "
                                "set camera.preset to a driving camera or custom")
        return None
    out = {k: v for k, v in CAMERA_DEFAULTS.items() if v is not None}
    out.update(CAMERA_PRESETS.get(name, {}))
    out.update({k: v for k, v in given.items() if v is not None})
    for k in ("width", "height"):
        if out.get(k) is None:
            raise err(k, "expected an integer >= 16, got None (custom cameras need width and height)")
    if out.get("fx") is None and out.get("hfov_deg") is not None:
        out["fx"] = out["width"] / 2.0 / math.tan(math.radians(out["hfov_deg"]) / 2.0)
    if out.get("fy") is None:
        out["fy"] = out.get("fx")
    for k, default in (("cx", out["width"] / 2.0), ("cy", out["height"] / 2.0)):
        if out.get(k) is None:
            out[k] = default
    for k in ("fx", "fy", "height_m"):
        if out.get(k) is None:
            raise err(k, "expected a positive number, got None" + (" (custom cameras need fx or hfov_deg)" if k == "fx" else ""))
    s = float(out.pop("scale"))
    out.pop("hfov_deg", None)
    res = {"preset": name, "width": int(round(out["width"] * s)), "height": int(round(out["height"] * s)),
           "fx": out["fx"] * s, "fy": out["fy"] * s, "cx": out["cx"] * s, "cy": out["cy"] * s,
           "height_m": float(out["height_m"]), "pitch_deg": float(out["pitch_deg"]), "roll_deg": float(out["roll_deg"])}
    return {k: (float(v) if isinstance(v, float) else v) for k, v in res.items()}


# ------------------------------------------------------------------ what is drawn

class PoseRanges(Block):
    """`pose`: [min, max] of each of the 8 pose fields (degrees, metres; cyclist_formats.pose)."""
    theta_p_deg: Range() = [0, 360]
    theta_s_deg: Range() = [-30, 30]
    theta_x_deg: Range() = [-5, 5]
    theta_y_deg: Range() = [-180, 180]
    theta_z_deg: Range() = [-5, 5]
    t_x_m: Range() = [0, 0]
    t_y_m: Range() = [0, 0]
    t_z_m: Range() = [0, 0]


# the order of the draws (generate.draw); the keys are the contract's field names,
# cyclist_formats.pose.POSE_FIELDS (not imported: it loads numpy, and --help reads this module)
POSE_KEYS = tuple(PoseRanges.model_fields)


class Views(Block):
    """`views`: the ring camera's draws (cyclist and bike-only modes)."""
    azimuth_deg: Range() = [-180, 180]
    elevation_deg: Range(-89, 89) = [0, 25]
    distance_m: Range(0.5, None) = [10, 14]
    focal_px: Optional[Positive] = Field(None, description="null: the ring's 2084.97 px scaled to image_size")
    centre_jitter_m: Annotated[Number, Field(ge=0)] = 0.1


class Street(Block):
    """`street` (street and frames modes): counts, distances and headings of the instances."""
    cyclists: IntRange(0, 64) = [1, 6]
    parked_bikes: IntRange(0, 64) = [0, 1]
    distance_m: Range(0.5, None) = [3, 60]
    lateral_m: Range() = [-15, 15]
    border_margin: Annotated[Number, Field(ge=0, le=1)] = 0.1
    heading: Literal["road", "uniform"] = "road"
    road_heading_deg: Annotated[Number, Field(ge=-360, le=360)] = 0.0
    heading_spread_deg: Annotated[Number, Field(ge=0, le=180)] = 15.0
    oncoming_share: Annotated[Number, Field(ge=0, le=1)] = 0.4
    footprint_radius_m: Annotated[Number, Field(ge=0.05, le=10)] = 1.0
    max_tries: Annotated[Int, Field(ge=1)] = 50
    parked_steer_deg: Range(-90, 90) = [-40, 40]


class SceneTransform(Block):
    rotation_deg: Vec3 = [0, 0, 0]
    translation_m: Vec3 = [0, 0, 0]
    scale: Positive = 1.0


BackgroundKind = Literal["solid", "gradient", "noise", "images", "scene"]


class Backgrounds(Block):
    kinds: Annotated[list[BackgroundKind], Field(min_length=1)] = ["solid", "gradient", "noise"]
    images_dir: Optional[Str] = None
    image_files: Optional[list[Str]] = None
    scene_ply: Optional[Str] = None
    scene_transform: SceneTransform = Field(default_factory=SceneTransform)
    shadow: Bool = True
    shadow_opacity: Annotated[Number, Field(ge=0, le=0.99)] = 0.55


class Keypoints(Block):
    person: Literal["coco17", "smpl24"] = "coco17"
    tolerance_bike_m: Annotated[Number, Field(ge=0)] = 0.08
    tolerance_rider_m: Annotated[Number, Field(ge=0)] = 0.15


# ------------------------------------------------------------------ labels

NonEmpty = Annotated[Str, Field(min_length=1)]
Combined = Literal["cyclist", "motorcyclist"]


class LabelNames(Block):
    """Category names written into the labels (must differ)."""
    bicycle: NonEmpty = "bicycle"
    rider: NonEmpty = "person"
    cyclist: NonEmpty = "cyclist"
    motorcyclist: NonEmpty = "motorcyclist"
    motorcycle: NonEmpty = "motorcycle"
    scooter: NonEmpty = "scooter"


class LabelCombined(Block):
    """The combined (vehicle + rider) category of each vehicle."""
    bicycle: Combined = "cyclist"
    motorcycle: Combined = "motorcyclist"
    scooter: Combined = "cyclist"


VEHICLES = tuple(LabelCombined.model_fields)
DEFAULT_NAMES = defaults_of(LabelNames)
DEFAULT_COMBINED = defaults_of(LabelCombined)


class Labels(Block):
    formats: Annotated[list[Literal["coco", "kitti", "mot"]], Field(min_length=1,
                       description="mot (MOTChallenge) is a tracking format: sequences only")] = ["coco"]
    names: LabelNames = Field(default_factory=LabelNames)
    combined: LabelCombined = Field(default_factory=LabelCombined)
    vehicle_of: dict[str, Literal[VEHICLES]] = Field(default_factory=dict, description="bike id -> vehicle")


# ------------------------------------------------------------------ looks

class LodLevel(Block):
    below_px: Positive
    keep: Annotated[Number, Field(gt=0, le=1)]


class Lod(Block):
    """`lod` (splatting/cyclist/lod.py): instances shorter than a level's below_px on screen are
    rendered with `keep` of their Gaussians; off by default, on in the street preset."""
    enabled: Bool = False
    levels: list[LodLevel] = Field(default_factory=lambda: [LodLevel(**x) for x in DEFAULT_LEVELS])
    compensate: Annotated[Number, Field(ge=0, le=2)] = DEFAULT_COMPENSATE


class Appearance(Block):
    """`appearance` (splatting/cyclist/appearance.py): per instance, new colours for the listed
    regions (HSV: any hue, saturation and value in the ranges; each region kept as trained with
    keep_share) and a gain: brightness x white balance (+-white_balance per channel)."""
    enabled: Bool = False
    # hair and bag (the roster's looks) are opt-in: the default keeps every earlier config.json as it was
    regions: list[Literal[RECOLOUR + RECOLOUR_EXTRA]] = list(RECOLOUR)
    keep_share: Annotated[Number, Field(ge=0, le=1)] = 0.25
    saturation: Range(0, 1) = [0.15, 0.9]
    value: Range(0, 1) = [0.12, 0.95]
    brightness: Range(0.05, 4) = [0.75, 1.25]
    white_balance: Annotated[Number, Field(ge=0, le=0.5)] = 0.08
    # per-instance accessories (splatting/cyclist/accessories.py); each null = what the rider wears (its
    # trained avatar's look.json, else its roster look drawn per rider id), so earlier configs draw nothing
    # new and keep their bytes.  They act whether or not `enabled` (the colours) is on.
    helmet_share: Optional[Annotated[Number, Field(ge=0, le=1)]] = Field(
        None, description="per instance: share of riders wearing a helmet (null: the rider's own)")
    bag_share: Optional[Annotated[Number, Field(ge=0, le=1)]] = Field(
        None, description="per instance: share of riders wearing a backpack (null: the rider's own)")
    hair_styles: Optional[Annotated[list[Literal[HAIR_STYLES]], Field(min_length=1)]] = Field(
        None, description="per instance: a hair style drawn uniformly from these (null: the rider's own)")


class Lighting(Block):
    """`lighting` (splatting/dataset/lighting.py): baked = the trained colour; relit = a sun and
    sky drawn per image from these ranges, bikes and riders shaded from their relight channels."""
    mode: Literal["baked", "relit"] = "baked"
    elevation_deg: Range(0, 90) = [15, 75]
    azimuth_deg: Range(-360, 360) = [-180, 180]
    strength: Range(0, 1000) = [2, 5]
    sky: Range(0, 100) = [0.1, 0.6]
    sun_tint: Annotated[Number, Field(ge=0, lt=1)] = 0.15
    shadows: Bool = True


# ------------------------------------------------------------------ frames mode (docs/kitti_insert.md)

class Look(Block):
    """`insert.look`: the inserted cyclists lit and blurred as the frame."""
    match: Bool = True
    blur_sigma_px: AutoOr(0, 5) = "auto"
    noise_sigma: AutoOr(0, 0.2) = "auto"
    sun_elevation_deg: Annotated[Number, Field(ge=1, le=90)] = 45.0
    sun_azimuth_deg: Annotated[Number, Field(ge=-360, le=360)] = 120.0
    cast_shadow: Bool = True


class Insert(Block):
    """`insert`: how cyclists go into real frames (counts, distances and headings come from `street`)."""
    lidar: Bool = Field(True, description="use velodyne/ when present: plane fallback, road checks, occlusion, scan")
    box_margin_m: Annotated[Number, Field(ge=0, le=10, description="kept clear around every labelled 3D box")] = 0.5
    min_ground_points: Annotated[Int, Field(ge=0, description="LiDAR road points for a footprint to be seen road")] = 3
    camera_height_m: Annotated[Number, Field(ge=0.2, le=10, description="the level road below camera 0 "
                                                                         "when a frame has neither planes nor LiDAR")] = 1.65
    occlusion_margin_m: Annotated[Number, Field(ge=0, le=5, description="the frame hides an inserted pixel "
                                                                         "only when nearer by more than this")] = 0.3
    behind_cars_share: Annotated[Number, Field(ge=0, le=1, description="share of instances sought just beyond "
                                                                        "a labelled car")] = 0.0
    box_occluders: Bool = Field(True, description="the labelled 3D boxes, drawn solid, hide what is behind them")
    look: Look = Field(default_factory=Look)



# ------------------------------------------------------------------ street sequences (docs/sequences.md)

Share = Annotated[Number, Field(ge=0, le=1)]
# `sequence.manoeuvres`: a relative weight per manoeuvre (0 = never), one field each
Manoeuvres = type("Manoeuvres", (Block,), {
    "__doc__": "`sequence.manoeuvres`: relative weights of the manoeuvres (0 = never; not all 0).",
    "__annotations__": {m: Annotated[Number, Field(ge=0)] for m in MANOEUVRES},
    **{m: 1.0 for m in MANOEUVRES}})


class Ego(Block):
    motion: Literal["moving", "static"] = "moving"
    speed_mps: Range(0, 40) = [4.0, 10.0]


class Sequence(Block):
    """`sequence`: street sequences; `count` then counts sequences of `length` frames."""
    enabled: Bool = False
    length: Annotated[Int, Field(ge=2, le=100000, description="frames per sequence")] = 100
    fps: Annotated[Number, Field(ge=0.5, le=240, description="frame rate (KITTI's 10 Hz)")] = 10.0
    manoeuvres: Manoeuvres = Field(default_factory=Manoeuvres)
    speed_mps: Range(0.5, 15) = [2.0, 8.0]
    turn_radius_m: Range(2, 200) = Field([6.0, 20.0], description="tightest radius of a turn "
                                                                 "(raised above v^2 / max_lateral_accel)")
    max_lateral_accel_mps2: Annotated[Number, Field(ge=0.5, le=9.81)] = 3.0
    cadence_rpm: Range(20, 150) = Field([60.0, 90.0], description="cruising cadence; sets each cyclist's gear ratio")
    lane_half_width_m: Annotated[Number, Field(ge=0.5, le=10, description="the ego's lane about its path X = 0 "
                                                                         "(the crossing label)")] = 1.5
    ego: Ego = Field(default_factory=Ego)
    signal_share: Annotated[Share, Field(description="share of turns, crossings and stops announced by an "
                                                     "arm signal")] = 0.6
    signal_lead_s: Range(0, 30) = Field([1.0, 3.0], description="the signal shows from this long before the "
                                                                "turn / braking until it starts")
    one_handed_share: Annotated[Share, Field(description="share of `straight` riders riding one-handed "
                                                         "for a while")] = 0.2
    exposure_s: Annotated[Number, Field(ge=0, le=1, description="motion blur: shutter time (0 = off: the "
                                                                "instant's image)")] = 0.0
    blur_subframes: Annotated[Int, Field(ge=1, le=99, description="renders averaged over the exposure (odd: "
                                                                  "the middle one is the frame's instant)")] = 5
    still_signal_share: Annotated[Share, Field(description="still sets (enabled false): share of riders "
                                                           "showing an arm signal")] = 0.0


# ------------------------------------------------------------------ the whole config

def _ids(v):
    if not (v == "all" or (isinstance(v, list) and v and all(isinstance(x, str) and x for x in v))):
        raise PydanticCustomError("ids", "expected 'all' or a non-empty list of ids")
    return v


def _safe_name(v):
    if not (isinstance(v, str) and v):
        raise PydanticCustomError("name", "expected a non-empty string")
    if not checks.SAFE_NAME.match(v):  # it names the default output folder out/datasets/<name>
        raise PydanticCustomError("name", "expected a name of letters, digits, '.', '_' or '-' (starting with a "
                                          "letter or digit, at most 100)")
    return v


Ids = Annotated[Union[Literal["all"], list[str]], PlainValidator(_ids, json_schema_input_type=Union[Literal["all"], list[str]])]
SafeName = Annotated[str, PlainValidator(_safe_name, json_schema_input_type=str)]


class DatasetConfig(Block):
    """A dataset config (blend_assets/datasets/*.yaml).  Field order is the stored record's order."""
    name: SafeName = Field("dataset", description="the dataset's name (default output out/datasets/NAME)")
    mode: Literal["cyclist", "bike-only", "street", "frames"] = "cyclist"
    seed: Annotated[Int, Field(ge=0, description="seed of every draw (a sample is a function of seed and index)")] = 0
    count: Annotated[Int, Field(ge=1, description="number of images")] = 100
    image_size: Annotated[Int, Field(ge=16, description="square image side in pixels (ring camera)")] = 512
    riders: Ids = Field(["m_adult_average_185"], description="rider ids ('all': the roster)")
    riders_root: Str = Field("data/riders", description="folder of trained rider avatars (ID/)")
    bikes: Ids = Field("all", description="bike ids ('all': every bike folder under bikes_root)")
    bikes_root: Str = Field("out/bikes", description="folder of bike folders")
    synthetic_assets: Literal["auto", "always", "never"] = Field(
        "auto", description="auto: trained Gaussians where they exist, else stand-ins")
    synthetic_gaussians_per_part: Annotated[Int, Field(ge=10)] = 3000
    rider_gaussians: Optional[Annotated[Int, Field(ge=100)]] = Field(
        None, description="subsample an untrained (mesh) avatar; null = every vertex")
    ik_iterations: Annotated[Int, Field(ge=1)] = 50
    pose: PoseRanges = Field(default_factory=PoseRanges)
    views: Views = Field(default_factory=Views)
    camera: Camera = Field(default_factory=Camera)
    street: Street = Field(default_factory=Street)
    backgrounds: Backgrounds = Field(default_factory=Backgrounds)
    keypoints: Keypoints = Field(default_factory=Keypoints)
    labels: Labels = Field(default_factory=Labels)
    depth_maps: Bool = False
    amodal_max_px: Optional[Annotated[Int, Field(ge=32)]] = Field(
        None, description="amodal masks of larger parts at reduced resolution (speed)")
    png_compress_level: Annotated[Int, Field(ge=0, le=9)] = 4
    lod: Lod = Field(default_factory=Lod)
    appearance: Appearance = Field(default_factory=Appearance)
    lighting: Lighting = Field(default_factory=Lighting)
    frames: Optional[Str] = Field(None, description="frames mode: the KITTI object folder (image_2, calib, label_2; "
                                                    "planes, velodyne) to insert cyclists into (docs/kitti_insert.md)")
    insert: Insert = Field(default_factory=Insert)
    sequence: Sequence = Field(default_factory=Sequence)

    @model_validator(mode="after")
    def _across_fields(self):
        """Checks that span fields; one UserError naming the field (raised as is through pydantic)."""
        cam = resolve_camera(self.camera)
        if self.mode == "street" and cam is None:
            raise field_error("camera.preset", "street mode needs a driving camera (kitti, nuscenes, waymo, dashcam, custom)")
        if self.mode != "street" and cam is not None:
            raise field_error("camera.preset", f"{self.mode} mode uses the ring camera (set mode: street for driving cameras)")
        b = self.backgrounds
        if "images" in b.kinds and b.images_dir is None and b.image_files is None:
            raise field_error("backgrounds.images_dir", "the 'images' background needs a folder of JPG/PNG files")
        if "scene" in b.kinds and b.scene_ply is None:
            raise field_error("backgrounds.scene_ply", "the 'scene' background needs a 3DGS .ply (INRIA layout)")
        names = self.labels.names.model_dump()
        if len(set(names.values())) != len(names):
            raise field_error("labels.names", "category names must differ")
        by_h = sorted(self.lod.levels, key=lambda x: -x.below_px)
        if any(b.keep > a.keep for a, b in zip(by_h, by_h[1:])):
            raise field_error("lod.levels", "a level for shorter instances must not keep more Gaussians")
        if self.mode == "frames" and not self.frames:
            raise field_error("frames", f"frames mode needs a KITTI object folder (or --frames DIR), got {self.frames!r}")
        a = self.appearance
        if self.lighting.mode == "relit" and (a.helmet_share, a.bag_share, a.hair_styles) != (None, None, None):
            raise field_error("appearance.helmet_share", "per-instance accessories (helmet_share, bag_share, hair_styles) "
                                                         "need baked lighting (relight channels are per trained avatar)")
        self._check_sequence()
        return self

    def _check_sequence(self):
        sq = self.sequence
        if not sq.enabled:
            if "mot" in self.labels.formats:
                raise field_error("labels.formats", "mot (MOTChallenge) is a tracking format: it needs sequence.enabled: true")
            return
        if self.mode not in ("street", "frames"):
            raise field_error("sequence.enabled", f"sequences are street scenes or KITTI frames (mode: street or "
                                                  f"frames), got mode {self.mode!r}")
        if self.mode == "frames" and sq.ego.motion != "static":
            raise field_error("sequence.ego.motion", "a KITTI frame is one instant: its camera stands still "
                                                     "(set sequence.ego.motion: static)")
        if self.lighting.mode != "baked":
            raise field_error("lighting.mode", "sequences use the baked light (a relit sun per frame would flicker)")
        w = sq.manoeuvres.model_dump()
        if not sum(w.values()) > 0:
            raise field_error("sequence.manoeuvres", f"expected weights >= 0, not all 0, got {w!r}")
        if sq.exposure_s > 1.0 / sq.fps:
            raise field_error("sequence.exposure_s", f"the shutter cannot stay open longer than a frame (1 / fps = "
                              f"{1.0 / sq.fps:.4g} s), got {sq.exposure_s!r}")
        if sq.blur_subframes % 2 != 1:
            raise field_error("sequence.blur_subframes", f"expected an odd integer within 1..99, got {sq.blur_subframes!r}")


def require_config(cfg, who="the dataset generator"):
    """The generator takes a validated DatasetConfig, not a mapping: a dict here would skip the checks
    and the defaults (config.validate / load_config make the model, once, where the YAML is read)."""
    if not isinstance(cfg, DatasetConfig):
        raise TypeError(f"{who} takes a DatasetConfig (splatting.dataset.config.validate / load_config), "
                        f"got {type(cfg).__name__}")
    return cfg


# the top-level fields the dataset command overrides with flags of the same name
CLI_OVERRIDES = ("count", "seed", "image_size", "bikes_root", "bikes", "riders", "riders_root", "frames")

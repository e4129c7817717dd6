"""The dataset config's typed models (splatting/dataset/config_models.py): every preset validates,
the validated config is the dict the hand-written checks made (snapshot taken with the code before
the models: same keys, order, values and types, so config.json keeps its bytes), bad values give one
line naming the field, and the command's override flags come from the models."""
import argparse
import json
import os

import pytest
import yaml

from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import Block, Field, Int, add_model_arguments, overrides_of
from splatting.dataset import config
from splatting.dataset.config_models import CLI_OVERRIDES, DatasetConfig

SNAP = os.path.join(os.path.dirname(os.path.abspath(__file__)), "snapshots", "dataset_configs.json")
PRESETS = sorted(f[:-5] for f in os.listdir(config.PRESET_DIR) if f.endswith(".yaml"))


def test_every_preset_file_is_a_valid_config():
    assert {"bike-only", "cyclist", "street", "kitti-insert", "street-sequence"} <= set(PRESETS)
    for name in PRESETS:
        with open(os.path.join(config.PRESET_DIR, name + ".yaml"), encoding="utf-8") as f:
            raw = yaml.safe_load(f)
        model = DatasetConfig.model_validate(raw)  # extra="forbid": no stray or misspelt field
        assert model.mode == raw["mode"] and model.name == raw["name"], name


def _resolved():
    """The cases the snapshot holds, validated by today's code."""
    out = {"defaults": config.validate({})}
    for p in ("bike-only", "cyclist", "street", "kitti-insert", "street-sequence"):
        out[p] = config.load_config(preset=p)
    out["frames_small"] = config.validate({
        "mode": "frames", "frames": "x", "street": {"road_heading_deg": 0},
        "lod": {"levels": [{"below_px": 50, "keep": 0.5}]},
        "labels": {"vehicle_of": {"a": "scooter"}, "names": {"rider": "human"}}, "camera": {"pitch_deg": 0}})
    out["street_custom"] = config.validate({
        "mode": "street", "camera": {"preset": "custom", "width": 640, "height": 480, "fx": 500, "height_m": 1.2},
        "backgrounds": {"kinds": ["images"], "images_dir": "d"}})
    return {k: v.model_dump() for k, v in out.items()}


def test_validated_configs_are_those_of_the_hand_written_checks():
    """Byte for byte (key order, 0 vs 0.0): config.json beside a dataset is this dict's JSON, and a
    resumed run compares it with the stored one."""
    with open(SNAP) as f:
        want = f.read()
    assert json.dumps(_resolved(), indent=1) + "\n" == want


def test_pose_keys_are_the_contracts_pose_fields():
    from cyclist_formats.pose import POSE_FIELDS
    from splatting.dataset.config_models import POSE_KEYS
    assert POSE_KEYS == POSE_FIELDS


def test_values_keep_the_type_they_were_written_with():
    cfg = config.validate({"street": {"road_heading_deg": 0, "distance_m": [3, 60.5]}, "views": {"centre_jitter_m": 1}})
    assert type(cfg.street.road_heading_deg) is int and cfg.street.distance_m == [3, 60.5]
    assert type(cfg.street.distance_m[0]) is int and type(cfg.views.centre_jitter_m) is int


@pytest.mark.parametrize("patch, field, words", [
    ({"street": {"distance_m": [0.1, 5]}}, "street.distance_m", "within [0.5, None]"),
    ({"street": {"border_margin": float("nan")}}, "street.border_margin", "finite"),
    ({"street": {"oncoming_share": 1.5}}, "street.oncoming_share", "<= 1"),
    ({"views": {"centre_jitter_m": float("inf")}}, "views.centre_jitter_m", "finite"),
    ({"count": True}, "count", "an integer"),
    ({"png_compress_level": 10}, "png_compress_level", "<= 9"),
    ({"depth_maps": "yes"}, "depth_maps", "true or false"),
    ({"insert": {"look": {"noise_sigma": "high"}}}, "insert.look.noise_sigma", "auto or a number"),
    ({"insert": {"look": {"sun_elevation_deg": 0}}}, "insert.look.sun_elevation_deg", ">= 1"),
    ({"insert": {"lidar_x": 1}}, "insert.lidar_x", "unknown field (known: lidar,"),
    ({"lod": {"levels": [{"below_px": 50, "keep": 0}]}}, "lod.levels[0].keep", "> 0"),
    ({"lod": {"levels": [{"below_px": 50}]}}, "lod.levels[0].keep", "missing"),
    ({"backgrounds": {"kinds": ["solid", "photo"]}}, "backgrounds.kinds", "item 1"),
    ({"backgrounds": {"scene_transform": {"scale": 0}}}, "backgrounds.scene_transform.scale", "> 0"),
    ({"appearance": {"brightness": [0.01, 2]}}, "appearance.brightness", "within [0.05, 4]"),
    ({"labels": {"names": {"rider": ""}}}, "labels.names.rider", "at least 1"),
    ({"camera": {"preset": "kitti", "width": 8}}, "camera.width", ">= 16"),
    ({"mode": "street", "camera": {"preset": "dashcam", "hfov_deg": 175}}, "camera.hfov_deg", "<= 170"),
    ({"mode": "bike-only", "camera": {"preset": "kitti"}}, "camera.preset", "ring camera"),
    ({"street": []}, "street", "expected a mapping, got list"),
    ({"name": "a/b"}, "name", "letters, digits"),
])
def test_bad_values_give_one_line_naming_the_field(patch, field, words):
    with pytest.raises(UserError) as e:
        config.validate(patch)
    msg = str(e.value)
    assert msg.startswith(f"config field '{field}': ") and words in msg and len(msg.splitlines()) == 1, msg


def test_the_json_schema_comes_from_the_models():
    s = DatasetConfig.model_json_schema()
    assert s["additionalProperties"] is False
    assert set(s["properties"]) == set(config.DEFAULTS)
    street = s["$defs"]["Street"]
    assert street["additionalProperties"] is False
    assert street["properties"]["oncoming_share"]["default"] == 0.4


def _parser():
    p = argparse.ArgumentParser()
    add_model_arguments(p, DatasetConfig, CLI_OVERRIDES)
    return p


def test_override_flags_are_typed_and_described_by_the_models():
    p = _parser()
    a = p.parse_args(["--count", "3", "--bikes", "x", "y", "--riders-root", "r", "--image-size", "64"])
    o = overrides_of(a, CLI_OVERRIDES)
    assert o["count"] == 3 and o["image_size"] == 64 and o["bikes"] == ["x", "y"] and o["riders_root"] == "r"
    assert o["seed"] is None and o["frames"] is None
    with pytest.raises(SystemExit):
        p.parse_args(["--count", "many"])
    helps = {a.dest: a.help for a in p._actions}
    for name in CLI_OVERRIDES:
        assert DatasetConfig.model_fields[name].description in helps[name], name


def test_a_field_without_a_description_cannot_become_a_flag():
    class M(Block):
        n: Int = 1
        m: Int = Field(2, description="m things")
    p = argparse.ArgumentParser()
    add_model_arguments(p, M, ("m",))
    with pytest.raises(ValueError, match="M.n has no description"):
        add_model_arguments(p, M, ("n",))


def test_the_dataset_command_overrides_through_the_models(tmp_path):
    """--count and --bikes reach the config (and a bad --count still fails on the field)."""
    from splatting.dataset.command import add_arguments
    p = argparse.ArgumentParser()
    add_arguments(p)
    a = p.parse_args(["--preset", "cyclist", "--count", "2", "--bikes", "b1"])
    cfg = config.load_config(preset="cyclist", overrides=overrides_of(a, CLI_OVERRIDES))
    assert cfg.count == 2 and cfg.bikes == ["b1"] and cfg.riders == "all" and cfg.seed == 0
    with pytest.raises(UserError, match="config field 'count'"):
        config.load_config(preset="cyclist", overrides={"count": 0})

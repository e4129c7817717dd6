"""Command lines derived from the configs (cyclist_formats/typed_config.py): the training stages'
pydantic configs give their options, defaults, types, ranges and choices to `train`,
`bike-posed-train` and `rider-posed-train` through the one builder the dataset command uses, so a
default is written once (in the model), a parsed command line gives that config back, and a bad
value is one line naming its flag before any work starts."""
import argparse
import json
import os
import subprocess
import sys
import typing

import pytest

from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import (Block, Bool, Field, Int, Number, add_model_arguments, model_from_args,
                                          options_of, record_of, updated, validate)
from splatting.bike.command import PosedTrain
from splatting.bike.posed_config import PosedTrainConfig
from splatting.relight import command as relight_command
from splatting.relight.fit import RelightFitConfig
from splatting.rider.command import Avatar as RiderAvatar, PosedTrain as RiderPosedTrain
from splatting.rider.posed_config import PosedTrainConfig as RiderPosedTrainConfig
from splatting.training import command as train_command
from splatting.training.strategy import DensifyConfig
from splatting.training.config import FineTuneRates, TrainConfig

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# the dataclass defaults these models replaced, written out: a default that moves is a change to
# every record and every resumed build, never a side effect of the conversion
OLD_DENSIFY = {"grad_threshold": 0.0002, "percent_dense": 0.01, "split_n": 2, "start": 200, "stop": 2500,
               "every": 100, "reset_every": 0, "min_opacity": 0.005, "max_screen_frac": 0.15,
               "max_world_frac": 0.1, "max_gaussians": 15000, "hull_prune": True}
OLD_TRAIN = {"iterations": 3000, "time_budget_s": 600.0, "sh_degree": 0, "holdout": (3, 12, 21, 30), "seed": 0,
             "antialiased": False, "eps2d": 0.3, "threads": 1, "resolution_schedule": ((0, 1.0),),
             "crop_margin_px": 8, "lr_means": 1.6e-4, "lr_means_final": 1.6e-6, "lr_sh0": 2.5e-3,
             "lr_shN": 2.5e-3 / 20, "lr_opacity": 0.05, "lr_scales": 5e-3, "lr_quats": 1e-3, "lambda_dssim": 0.2,
             "init_max_points": 10000, "init_opacity": 0.1, "eval_every": 200, "patience": 3, "min_delta_db": 0.05,
             "progress": True, "strategy": "default"}
OLD_RATES = {"lr_means": 1.6e-5, "lr_sh0": 2.5e-3, "lr_opacity": 0.02, "lr_scales": 2.5e-3, "lr_quats": 1e-3,
             "lambda_dssim": 0.2}
OLD_BIKE_POSED = {**OLD_RATES, "poses": 144, "iterations": 6000, "rest_fraction": 0.25, "samples": 128,
                  "denoise": "FAST", "seed": 0, "crop_margin_px": 8, "sh_degree": 1, "lr_shN": 2.5e-3,
                  "densify": False, "densify_max": 30000, "lr_decay": 1.0, "lr_tail": 0, "eps2d": 0.3,
                  "progress": True}
OLD_RIDER_POSED = {**OLD_RATES, "poses": 4, "cameras": 8, "iterations": 600, "scale": 1.0, "rest_fraction": 0.25,
                   "samples": None, "seed": 0, "progress": True}

OLD_RELIGHT = {"iterations": 300, "lr": 0.05, "max_size": 512, "holdout": (3, 12, 21, 30), "shading_loss": 1.0,
               "relit_loss": 0.0, "view_normals": False, "view_normal_penalty": 0.0, "seed": 0, "progress": True}


def _parser(add):
    p = argparse.ArgumentParser()
    add(p)
    return p


def _options(p):
    return {a.dest: a for a in p._actions if a.option_strings}


def _typed_equal(got, want):
    """Equal values of the same types (3000 is not 3000.0 in a record's bytes)."""
    assert list(got) == list(want), (list(got), list(want))
    for k, v in want.items():
        assert got[k] == v and type(got[k]) is type(v), (k, got[k], v)


@pytest.mark.parametrize("model, old", [(DensifyConfig, OLD_DENSIFY), (FineTuneRates, OLD_RATES),
                                        (PosedTrainConfig, OLD_BIKE_POSED), (RiderPosedTrainConfig, OLD_RIDER_POSED),
                                        (RelightFitConfig, OLD_RELIGHT)])
def test_defaults_are_the_dataclass_defaults(model, old):
    _typed_equal(dict(vars(model())), old)


def test_the_strategy_names_are_the_strategies():
    from splatting.training.config import STRATEGY_NAMES
    from splatting.training.strategy import STRATEGIES
    assert STRATEGY_NAMES == tuple(STRATEGIES) == typing.get_args(TrainConfig.model_fields["strategy"].annotation)


def test_train_defaults_are_the_dataclass_defaults():
    d = TrainConfig()
    _typed_equal({k: getattr(d, k) for k in OLD_TRAIN}, OLD_TRAIN)
    assert list(TrainConfig.model_fields) == list(OLD_TRAIN) + ["densify"]
    _typed_equal(dict(vars(d.densify)), OLD_DENSIFY)


# (command name, add_arguments, model, the fields its command line exposes, options not in the model)
COMMANDS = [
    ("train", train_command.add_arguments, TrainConfig,
     ["iterations", "time_budget_s", "sh_degree", "holdout", "seed", "antialiased", "eps2d", "threads", "strategy",
      "densify.max_gaussians"], {"help", "views", "out", "no_early_stop", "quiet"}),
    ("bike-posed-train", PosedTrain.add_arguments, PosedTrainConfig,
     ["poses", "iterations", "samples", "sh_degree", "densify", "densify_max", "lr_decay", "lr_tail", "eps2d"],
     {"help", "bike", "from_rest", "render_threads", "quiet"}),
    ("rider-posed-train", RiderPosedTrain.add_arguments, RiderPosedTrainConfig,
     ["poses", "cameras", "iterations", "scale", "samples"], {"help", "avatar", "quiet"}),
    ("relight-fit", relight_command.add_arguments, RelightFitConfig,
     ["iterations", "max_size", "relit_loss", "view_normals"], {"help", "views", "bike", "ply", "quiet"}),
]


@pytest.mark.parametrize("name, add, model, fields, others", COMMANDS, ids=[c[0] for c in COMMANDS])
def test_every_flag_is_a_model_field_and_back(name, add, model, fields, others):
    """The options are exactly the described fields (nested blocks' too), each flag named after its
    field, its --help the field's description and default; no other flag reaches the config."""
    assert list(options_of(model)) == fields
    opts = _options(_parser(add))
    assert set(opts) == {f.replace(".", "_") for f in fields} | others
    for path in fields:
        owner = model
        for part in path.split(".")[:-1]:
            owner = type(getattr(owner(), part))
        f = owner.model_fields[path.rsplit(".", 1)[-1]]
        a = opts[path.replace(".", "_")]
        assert a.option_strings[0] == "--" + path.rsplit(".", 1)[-1].replace("_", "-")
        assert a.default is None and f.description.replace("%", "%%") in a.help, path
        assert "(default " in a.help, path


def test_rider_avatar_trains_with_the_trainers_fields():
    """rider-avatar's training flags are TrainConfig fields through the same builder: no flag of its
    own, the trainer's defaults."""
    p = _parser(RiderAvatar.add_arguments)
    opts = _options(p)
    assert set(opts) == {"help", "id", "out", "samples", "size", "bare", "iterations", "time_budget_s",
                         "densify_max_gaussians", "threads"}
    assert opts["densify_max_gaussians"].option_strings == ["--max-gaussians"]
    assert RiderAvatar.train_config(p.parse_args(["--id", "r"])) == TrainConfig()
    cfg = RiderAvatar.train_config(p.parse_args(["--id", "r", "--iterations", "1500", "--max-gaussians", "9000"]))
    assert cfg == TrainConfig(iterations=1500, densify=DensifyConfig(max_gaussians=9000))


def test_posed_train_options_are_its_config_fields():
    p = _parser(PosedTrain.add_arguments)
    opts = _options(p)
    assert opts["sh_degree"].choices == (0, 1, 2)
    # no options given: the model's defaults (with progress from --quiet)
    args = p.parse_args(["--bike", "b", "--quiet"])
    assert PosedTrain.config_from_args(args) == PosedTrainConfig(progress=False)
    args = p.parse_args(["--bike", "b", "--poses", "200", "--densify", "--lr-decay", "0.5", "--sh-degree", "2"])
    assert PosedTrain.config_from_args(args) == PosedTrainConfig(poses=200, densify=True, lr_decay=0.5, sh_degree=2)
    with pytest.raises(SystemExit):
        p.parse_args(["--bike", "b", "--poses", "many"])


def test_rider_posed_train_options_are_its_config_fields():
    p = _parser(RiderPosedTrain.add_arguments)
    a = p.parse_args(["--avatar", "a", "--quiet"])
    assert model_from_args(RiderPosedTrainConfig, a, options_of(RiderPosedTrainConfig), progress=False) \
        == RiderPosedTrainConfig(progress=False)
    a = p.parse_args(["--avatar", "a", "--scale", "0.5", "--samples", "16"])
    cfg = model_from_args(RiderPosedTrainConfig, a, options_of(RiderPosedTrainConfig))
    assert cfg.scale == 0.5 and cfg.samples == 16 and cfg.poses == 4


def test_train_options_reach_the_nested_densify_config_without_touching_the_defaults():
    p = _parser(train_command.add_arguments)
    args = p.parse_args(["--views", "v", "--max-gaussians", "123", "--holdout", "1,2", "--antialiased"])
    cfg = train_command.config_from_args(args)
    assert cfg.densify.max_gaussians == 123 and cfg.holdout == (1, 2) and cfg.antialiased is True
    assert TrainConfig().densify.max_gaussians != 123
    base = TrainConfig(progress=False)
    same = train_command.config_from_args(p.parse_args(["--views", "v", "--quiet"]))
    assert same == base
    assert train_command.config_from_args(p.parse_args(["--views", "v", "--no-early-stop"])).patience == 10 ** 9


def test_a_bad_integer_list_is_one_line():
    p = _parser(train_command.add_arguments)
    with pytest.raises(UserError, match=r"--holdout wants comma-separated integers, got '1,x'"):
        train_command.config_from_args(p.parse_args(["--views", "v", "--holdout", "1,x"]))


def test_nested_fields_become_options_named_after_themselves():
    class Inner(Block):
        k: Int = Field(2, description="k things")
        quiet: Int = 3

    class Outer(Block):
        a: Number = Field(0.5, description="a share")
        hidden: Int = 7
        on: Bool = Field(False, description="switch")
        inner: Inner = Field(default_factory=Inner)

    assert options_of(Outer) == ("a", "on", "inner.k")
    p = argparse.ArgumentParser()
    add_model_arguments(p, Outer, options_of(Outer), " (default {default})")
    assert set(_options(p)) == {"help", "a", "on", "inner_k"}
    assert _options(p)["inner_k"].help == "k things (default 2)"
    cfg = model_from_args(Outer, p.parse_args(["--a", "0.25", "--k", "5", "--on"]), options_of(Outer), hidden=8)
    assert cfg == Outer(a=0.25, hidden=8, on=True, inner=Inner(k=5))
    assert model_from_args(Outer, p.parse_args(["--no-on"]), options_of(Outer)) == Outer()
    with pytest.raises(UserError, match=r"^--k must be an integer, got '5'$"):
        model_from_args(Outer, argparse.Namespace(a=None, on=None, inner_k="5"), options_of(Outer))


# -------------------------------------------------- bad values: one line naming the field, exit 2

BAD = [
    ("train", ["--views", "v", "--eps2d", "nan"], "--eps2d must be a finite number, got nan"),
    ("train", ["--views", "v", "--eps2d", "11"], "--eps2d must be <= 10, got 11.0"),
    ("train", ["--views", "v", "--iterations", "0"], "--iterations must be >= 1, got 0"),
    ("train", ["--views", "v", "--time-budget-s", "inf"], "--time-budget-s must be a finite number"),
    ("train", ["--views", "v", "--holdout", "1,-2"], "--holdout item 1 must be >= 0, got -2"),
    ("train", ["--views", "v", "--max-gaussians", "0"], "--max-gaussians must be >= 1, got 0"),
    ("train", ["--views", "v", "--seed", "-1"], "--seed must be >= 0, got -1"),
    ("bike-posed-train", ["--bike", ".", "--lr-decay", "nan"], "--lr-decay must be a finite number"),
    ("bike-posed-train", ["--bike", ".", "--poses", "4"], "--poses must be >= 5, got 4"),
    ("bike-posed-train", ["--bike", ".", "--iterations", "10", "--lr-tail", "11"],
     "--lr-tail must be <= iterations (10), got 11"),
    ("bike-posed-train", ["--bike", ".", "--samples", "0"], "--samples must be >= 1, got 0"),
    ("rider-posed-train", ["--avatar", ".", "--scale", "nan"], "--scale must be a finite number"),
    ("rider-posed-train", ["--avatar", ".", "--scale", "2"], "--scale must be <= 1, got 2.0"),
    ("rider-posed-train", ["--avatar", ".", "--cameras", "1"], "--cameras must be >= 2, got 1"),
    ("relight-fit", ["--bike", ".", "--relit-loss", "nan"], "--relit-loss must be a finite number, got nan"),
    ("relight-fit", ["--views", ".", "--max-size", "8"], "--max-size must be >= 16, got 8"),
    ("relight-fit", ["--bike", ".", "--iterations", "0"], "--iterations must be >= 1, got 0"),
    ("rider-avatar", ["--id", "r", "--out", "a", "--time-budget-s", "nan"], "--time-budget-s must be a finite number"),
    ("rider-avatar", ["--id", "r", "--out", "a", "--threads", "0"], "--threads must be >= 1, got 0"),
]


@pytest.mark.parametrize("cmd, argv, msg", BAD, ids=[f"{c}{' '.join(a[2:])}" for c, a, _ in BAD])
def test_a_bad_value_is_one_line_naming_the_flag_before_any_work(cmd, argv, msg, tmp_path):
    """Exit 2, one stderr line naming the flag, nothing written (the work would need a real views
    folder / bike / avatar: the values are refused before those are even looked at)."""
    env = dict(os.environ, PYTHONPATH=ROOT)
    r = subprocess.run([sys.executable, "-m", "splatting", cmd, *argv], capture_output=True, text=True, env=env,
                       cwd=tmp_path)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and msg in lines[0], r.stderr
    assert os.listdir(tmp_path) == []


def test_a_wrong_type_or_unknown_field_in_code_or_a_recipe_is_one_line():
    from splatting.bike import recipes
    with pytest.raises(UserError, match=r"^config field 'iterations': expected an integer, got 3\.5$"):
        validate(TrainConfig, {"iterations": 3.5})
    with pytest.raises(UserError, match=r"^config field 'densify\.hull_prune': expected true or false, got 'yes'$"):
        validate(TrainConfig, {"densify": {"hull_prune": "yes"}})
    with pytest.raises(UserError, match=r"^config field 'sh_degree': expected one of 0, 1, 2, 3, got True$"):
        validate(TrainConfig, {"sh_degree": True})
    with pytest.raises(UserError, match=r"^config field 'densify\.max_gaussianz': unknown field \(known: "):
        validate(TrainConfig, {"densify": {"max_gaussianz": 5}})
    with pytest.raises(UserError, match=r"^recipe field 'lr_taill': unknown field"):
        recipes.posed_config({"train": {}, "posed": {"lr_taill": 5}})
    with pytest.raises(UserError, match=r"^config field 'threads': expected a value >= 1, got 0$"):
        updated(TrainConfig(), threads=0)
    with pytest.raises(UserError, match=r"^config field 'densify\.every': expected a value >= 1, got 0$"):
        updated(TrainConfig(), densify={"every": 0})
    with pytest.raises(Exception, match="frozen"):
        TrainConfig().iterations = 5  # a config is passed on unchanged: a change is a copy


def test_records_round_trip_byte_for_byte():
    """The record (PART.json / posed_train.json "config", the library's posed_<field>) is the model's
    fields in declaration order, values as given; read back it gives the same model and the same bytes."""
    cfg = updated(TrainConfig(), iterations=250, time_budget_s=900, holdout=(1, 5), antialiased=True,
                  densify={"max_gaussians": 2500})
    rec = record_of(cfg)
    text = json.dumps(rec)
    assert text.startswith('{"iterations": 250, "time_budget_s": 900, "sh_degree": 0, "holdout": [1, 5], ')
    assert text.endswith('"max_gaussians": 2500, "hull_prune": true}}')
    back = validate(TrainConfig, json.loads(text))
    assert back == cfg and json.dumps(record_of(back)) == text
    posed = PosedTrainConfig(poses=12, densify=True, lr_decay=0.5, eps2d=0.173, progress=False)
    prec = record_of(posed)
    assert "progress" not in prec and list(prec)[:2] == ["lr_means", "lr_sh0"] and list(prec)[-1] == "eps2d"
    back = validate(PosedTrainConfig, json.loads(json.dumps(prec)))
    assert back == posed.model_copy(update={"progress": True}) and record_of(back) == prec

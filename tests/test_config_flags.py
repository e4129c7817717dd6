"""Command lines derived from the configs (cyclist_formats/typed_config.py): the training stages'
dataclass configs give their options, defaults, types and choices to `train` and `bike-posed-train`,
so a default is written once (in the dataclass) and a parsed command line gives that config back."""
import argparse
import dataclasses

import pytest

from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import add_dataclass_arguments, dataclass_from_args
from splatting.bike.command import PosedTrain
from splatting.bike.posed_train import PosedTrainConfig
from splatting.training import command as train_command
from splatting.training.trainer import TrainConfig


def _parser(add):
    p = argparse.ArgumentParser()
    add(p)
    return p


def _options(p):
    return {a.dest: a for a in p._actions if a.option_strings}


def test_posed_train_options_are_its_config_fields():
    p = _parser(PosedTrain.add_arguments)
    opts = _options(p)
    exposed = [f.name for f in dataclasses.fields(PosedTrainConfig) if "help" in f.metadata]
    assert exposed == ["poses", "iterations", "samples", "sh_degree", "densify", "densify_max", "lr_decay",
                       "lr_tail", "eps2d"]
    d = PosedTrainConfig()
    for name in exposed:
        assert opts[name].default == getattr(d, name), name
    assert opts["sh_degree"].choices == (0, 1, 2)
    # no options given: the dataclass's defaults (with progress from --quiet)
    args = p.parse_args(["--bike", "b", "--quiet"])
    assert PosedTrain.config_from_args(args) == PosedTrainConfig(progress=False)
    args = p.parse_args(["--bike", "b", "--poses", "200", "--densify", "--lr-decay", "0.5", "--sh-degree", "2"])
    assert PosedTrain.config_from_args(args) == PosedTrainConfig(poses=200, densify=True, lr_decay=0.5, sh_degree=2)
    with pytest.raises(SystemExit):
        p.parse_args(["--bike", "b", "--poses", "many"])


def test_train_options_reach_the_nested_densify_config_without_touching_the_defaults():
    p = _parser(train_command.add_arguments)
    args = p.parse_args(["--views", "v", "--max-gaussians", "123", "--holdout", "1,2", "--antialiased"])
    cfg = train_command.config_from_args(args)
    assert cfg.densify.max_gaussians == 123 and cfg.holdout == (1, 2) and cfg.antialiased is True
    assert TrainConfig().densify.max_gaussians != 123
    base = TrainConfig(progress=False)
    same = train_command.config_from_args(p.parse_args(["--views", "v", "--quiet"]))
    assert same == base


def test_a_bad_integer_list_is_one_line():
    p = _parser(train_command.add_arguments)
    with pytest.raises(UserError, match=r"--holdout wants comma-separated integers, got '1,x'"):
        train_command.config_from_args(p.parse_args(["--views", "v", "--holdout", "1,x"]))


def test_only_fields_with_help_become_options():
    @dataclasses.dataclass
    class Inner:
        k: int = dataclasses.field(default=2, metadata={"help": "k things"})

    @dataclasses.dataclass
    class Outer:
        a: float = dataclasses.field(default=0.5, metadata={"help": "a share"})
        hidden: int = 7
        inner: Inner = dataclasses.field(default_factory=Inner)

    p = argparse.ArgumentParser()
    add_dataclass_arguments(p, Outer())
    assert set(_options(p)) == {"help", "a", "inner_k"}
    cfg = dataclass_from_args(p.parse_args(["--a", "0.25", "--k", "5"]), Outer(), hidden=8)
    assert cfg == Outer(a=0.25, hidden=8, inner=Inner(k=5))

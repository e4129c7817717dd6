"""splatting/bike/recipes.py: the asset recipes are the command lines docs/training.md gives."""
import argparse
import shlex

import pytest

from splatting.bike import posed_train, recipes
from splatting.bike.command import PosedTrain
from splatting.training import command

# the fidelity recipe as recipes.py's docstring (and docs/training.md) spell it
FIDELITY_TRAIN = "--antialiased"
FIDELITY_POSED = "--densify --densify-max 30000 --iterations 10000 --lr-decay 0.03 --lr-tail 2000 --sh-degree 2 --eps2d 0.173"


def _parse(add_arguments, line):
    p = argparse.ArgumentParser()
    add_arguments(p)
    return p.parse_args(shlex.split(line))


def test_fidelity_recipe_is_its_documented_command_lines():
    assert FIDELITY_POSED in " ".join(recipes.__doc__.split()) and FIDELITY_TRAIN in recipes.__doc__
    args = _parse(PosedTrain.add_arguments, "--bike b " + FIDELITY_POSED)
    assert recipes.posed_config("fidelity") == PosedTrain.config_from_args(args)
    assert recipes.posed_config("fidelity") != recipes.posed_config("default")
    targs = _parse(command.add_arguments, "--views v " + FIDELITY_TRAIN)
    assert recipes.train_config("fidelity", progress=True) == command.config_from_args(targs)
    assert recipes.train_config("fidelity").antialiased and not recipes.train_config("default").antialiased


def test_default_recipe_is_the_configs_defaults():
    assert recipes.posed_config("default") == posed_train.PosedTrainConfig()
    assert recipes.train_config("default", threads=2).threads == 2


def test_unknown_recipe_is_refused():
    with pytest.raises(ValueError, match="unknown recipe 'best'.*fidelity"):
        recipes.posed_config("best")


@pytest.mark.parametrize("name", sorted(recipes.RECIPES))
def test_every_recipe_makes_its_configs(name):
    """Each named recipe's train and posed blocks are valid configs (an unknown or mistyped field in
    a recipe raises UserError), and the library reads the recipe's Gaussian cap where the trainer does."""
    t = recipes.train_config(name)
    recipes.posed_config(name)
    cap = recipes.RECIPES[name]["train"].get("densify", {}).get("max_gaussians")
    if cap is not None:
        assert t.densify.max_gaussians == cap

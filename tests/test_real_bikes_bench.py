"""bench/real_bikes.py and the real-bike recipe (issue 27): the command refuses bad input with one
line before any work, the library build takes the recipe's part budget (explicit options still
win), and the model list names files that exist in the shared development set."""
import os
import subprocess
import sys

import pytest

from helpers import ROOT


def _settings(*argv):
    import argparse

    from splatting.library.command import add_arguments, settings_of
    p = argparse.ArgumentParser()
    add_arguments(p)
    return settings_of(p.parse_args(list(argv)))


def test_library_build_takes_the_recipe_part_budget():
    from splatting.bike.recipes import RECIPES
    real = RECIPES["real"]["train"]
    s = _settings("--recipe", "real")
    assert s.budget.iterations == real["iterations"] and s.budget.max_gaussians == real["densify_max_gaussians"]
    assert s.posed.iterations == RECIPES["real"]["posed"].get("iterations", 6000)
    d = _settings()   # the default recipe keeps the library's old budget
    assert (d.budget.iterations, d.budget.max_gaussians) == (3000, 15000)
    o = _settings("--recipe", "real", "--iterations", "77", "--max-gaussians", "1234")
    assert (o.budget.iterations, o.budget.max_gaussians) == (77, 1234)


@pytest.mark.parametrize("argv, words", [(["--models", "no_such_bike"], "unknown model 'no_such_bike'"),
                                         (["--poses", "0"], "--poses must be 1..1000")])
def test_bad_input_one_line_and_nothing_written(tmp_path, argv, words):
    out = tmp_path / "bench"
    r = subprocess.run([sys.executable, os.path.join(ROOT, "bench", "real_bikes.py"), "--out", str(out), *argv],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and words in r.stderr
    assert not out.exists()


def test_model_list_matches_the_shared_models():
    from bench.real_bikes import MODELS, models_dir
    d = models_dir()
    if d is None:
        pytest.skip("the shared real models (../shared/models)")
    missing = [m for m, rel in MODELS.items() if not os.path.isfile(os.path.join(d, rel))]
    assert missing == []
    assert len(MODELS) == 10

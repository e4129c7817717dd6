"""bench/real_bikes.py and the real-bike recipe (issue 27): the command refuses bad input with one
line before any work, the library build takes the recipe's part budget (explicit options still
win), and the model list names files that exist in the shared development set."""
import json
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
    assert s.budget.iterations == real["iterations"] and s.budget.max_gaussians == real["densify"]["max_gaussians"]
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


def _bike(root, bike_id, generator):
    d = root / "bikes" / bike_id
    d.mkdir(parents=True)
    (d / "bike.blend").write_bytes(b"")
    (d / "meta.json").write_text(json.dumps({"bike_id": bike_id, "generator": generator}))


def test_default_recipe_is_real_for_curated_bikes_and_default_for_procedural(tmp_path):
    """docs/curation.md: `library build` without --recipe builds bikes curated from downloaded
    models (meta.json generator "curated") with the real recipe at its 256 px / 128 spp, and
    procedural ones exactly as before (the default recipe's settings, key for key)."""
    from cyclist_formats.errors import UserError
    from splatting.bike.recipes import LIBRARY, RECIPES

    _bike(tmp_path, "real_one", "curated")
    _bike(tmp_path, "city_00", "procedural")
    out = ["--out", str(tmp_path)]
    real = _settings(*out, "--bikes", "real_one")
    assert real.record() == _settings(*out, "--bikes", "real_one", "--recipe", "real").record()
    assert real.budget.antialiased and real.posed.densify
    assert (real.budget.view_size, real.budget.samples) == (LIBRARY["real"]["view_size"], LIBRARY["real"]["samples"])
    assert real.budget.iterations == RECIPES["real"]["train"]["iterations"]
    proc = _settings(*out, "--bikes", "city_00")
    assert json.dumps(proc.record()) == json.dumps(_settings(*out, "--bikes", "city_00", "--recipe", "default").record())
    assert not proc.budget.antialiased and not proc.posed.densify
    assert (proc.budget.view_size, proc.budget.samples, proc.budget.iterations) == (512, None, 3000)
    assert real.record() != proc.record()
    # named explicitly, a recipe wins over the bikes' source; a mix has no one default
    assert _settings(*out, "--bikes", "real_one", "--recipe", "default").record() == proc.record()
    with pytest.raises(UserError, match="name --recipe"):
        _settings(*out)
    assert _settings(*out, "--recipe", "default").record() == proc.record()


def test_bench_builds_with_the_library_default(tmp_path):
    """bench/real_bikes.py measures what `library build` does on a curated bike by default: its
    command names no recipe, and its settings are the real recipe's."""
    from bench.real_bikes import RECIPE, build_cmd
    _bike(tmp_path, "real_one", "curated")
    argv = build_cmd(str(tmp_path), "real_one", 10)[5:]   # after `python -m splatting library build`
    assert "--recipe" not in argv and RECIPE == "real"
    assert _settings(*argv).record() == _settings(*argv, "--recipe", "real").record()

"""The library build's settings as typed objects (splatting/library/settings.py): bad values are one
line naming the field, unknown fields are errors, and the records written to disk are the flat
dicts the library wrote before the models (so existing libraries still match and resume)."""
import argparse
import json
import math
import os
import re

import pytest

from cyclist_formats.errors import UserError
from helpers import ROOT

BUDGET = dict(view_size=64, samples=None, iterations=10, time_budget_s=5.0, max_gaussians=1000, rider_iterations=10,
              gt_poses=2, gt_seed=0, riders_root="/r", posed_train=False)


def _settings(*argv):
    from splatting.library.command import add_arguments, settings_of
    p = argparse.ArgumentParser()
    add_arguments(p)
    return settings_of(p.parse_args(["--out", "lib", *argv]))


def test_the_record_is_the_flat_dict_libraries_were_built_with():
    """Written out by hand: the settings record of `library build --size 64 --no-posed-train` as
    library.json and the task records held it before the settings were models (key order too)."""
    s = _settings("--size", "64", "--no-posed-train")
    want = {"view_size": 64, "samples": None, "iterations": 3000, "time_budget_s": 600.0, "max_gaussians": 15000,
            "rider_iterations": 1500, "gt_poses": 3, "gt_seed": 0,
            "riders_root": os.path.abspath(os.path.join("data", "riders")), "posed_train": False}
    assert json.dumps(s.record()) == json.dumps(want)
    posed = _settings("--size", "64", "--posed-iterations", "20").record()
    keys = list(posed)
    assert keys[:10] == list(want) and posed["posed_train"] is True and posed["posed_iterations"] == 20
    assert all(k.startswith("posed_") for k in keys[10:]) and "posed_progress" not in posed
    fid = _settings("--recipe", "fidelity").record()
    assert list(fid)[10] == "antialiased" and fid["antialiased"] is True


@pytest.mark.parametrize("field, value, words", [
    ("view_size", 16, "library setting 'view_size': expected a value >= 32, got 16"),
    ("iterations", 0, "library setting 'iterations': expected a value >= 1, got 0"),
    ("time_budget_s", math.nan, "library setting 'time_budget_s': expected a finite number"),
    ("gt_poses", 2.0, "library setting 'gt_poses': expected an integer"),
    ("samples", 1 << 20, "library setting 'samples': expected a value <= 65536"),
    ("posed_train", "yes", "library setting 'posed_train': expected true or false"),
    ("colour", 1, "library setting 'colour': unknown field"),
])
def test_a_bad_budget_names_its_field_in_one_line(field, value, words):
    from splatting.library.settings import budget
    with pytest.raises(UserError) as e:
        budget(**dict(BUDGET, **{field: value}))
    assert str(e.value).startswith(words) and len(str(e.value).splitlines()) == 1, str(e.value)


def test_floors_have_their_ranges_and_defaults():
    from splatting.library.settings import FLOORS, Floors, floors
    assert Floors().record() == FLOORS == {"min_part_psnr": 20.0, "min_gt_iou": 0.85, "min_gt_box_psnr": 18.0,
                                           "min_rider_psnr": 20.0}
    with pytest.raises(UserError, match=r"^quality floor 'min_gt_iou': expected a value <= 1, got 2$"):
        floors(**dict(FLOORS, min_gt_iou=2))


def test_settings_hold_a_posed_configuration_exactly_when_the_stage_is_on():
    from splatting.bike.recipes import posed_config
    from splatting.library.settings import LibrarySettings, budget
    with pytest.raises(ValueError, match="posed configuration goes with budget.posed_train"):
        LibrarySettings(budget(**BUDGET), posed_config("default"))
    with pytest.raises(ValueError, match="posed configuration goes with budget.posed_train"):
        LibrarySettings(budget(**dict(BUDGET, posed_train=True)))
    with pytest.raises(TypeError, match="takes a Budget, got dict"):
        LibrarySettings(dict(BUDGET))


def test_the_library_tasks_read_attributes_not_dict_keys():
    """settings["x"] / s.get("x") reads of the settings in the task runners would not see the models."""
    with open(os.path.join(ROOT, "splatting", "library", "tasks.py"), encoding="utf-8") as f:
        text = f.read()
    bad = [line.strip() for line in text.splitlines()
           if re.search(r"""\bs(?:ettings)?\s*(?:\[\s*["']|\.get\()""", line.split("#", 1)[0])]
    assert not bad, bad

"""bench/train_parts.py resumes: a part trained with the same recipe is reused, anything else is retrained."""
import json
import os

from bench.train_parts import same_recipe, trained_with
from cyclist_formats.typed_config import record_of as config_dict, updated
from splatting.training.trainer import TrainConfig


def _part(tmp_path, cfg, stopped="iterations"):
    ply = tmp_path / "frame.ply"
    ply.write_bytes(b"ply\n")  # only its presence is checked
    (tmp_path / "frame.json").write_text(json.dumps({"psnr": 31.0, "stopped": stopped, "config": config_dict(cfg)}))
    return str(ply)


def test_same_recipe_is_reused(tmp_path):
    ply = _part(tmp_path, TrainConfig())
    assert trained_with(ply, TrainConfig())["psnr"] == 31.0
    # threads, progress and the wall-time cap do not change what was trained
    assert trained_with(ply, TrainConfig(threads=2, progress=False, time_budget_s=5.0)) is not None


def test_another_recipe_or_a_capped_run_is_retrained(tmp_path):
    ply = _part(tmp_path, TrainConfig())
    assert trained_with(ply, TrainConfig(iterations=TrainConfig().iterations + 1)) is None
    assert trained_with(ply, TrainConfig(antialiased=not TrainConfig().antialiased)) is None
    cfg = TrainConfig()
    cfg = updated(cfg, densify={"max_gaussians": cfg.densify.max_gaussians + 1})
    assert trained_with(ply, cfg) is None
    # stopped by the wall-time cap: its learning rate never finished decaying
    assert trained_with(_part(tmp_path, TrainConfig(), stopped="time_budget"), TrainConfig()) is None


def test_missing_or_unreadable_metrics(tmp_path):
    assert trained_with(str(tmp_path / "none.ply"), TrainConfig()) is None
    ply = _part(tmp_path, TrainConfig())
    (tmp_path / "frame.json").write_text("{not json")
    assert trained_with(ply, TrainConfig()) is None
    os.remove(tmp_path / "frame.json")
    assert trained_with(ply, TrainConfig()) is None


def test_same_recipe_compares_every_training_field():
    a = config_dict(TrainConfig())
    assert same_recipe(a, dict(a, threads=4))
    assert not same_recipe(a, dict(a, lr_opacity=a["lr_opacity"] * 2))

"""The dataset generator takes the validated DatasetConfig and reads its attributes (cfg.street.distance_m),
never a dict: no `cfg["..."]` reads come back into splatting/dataset, and a plain dict is refused
where the generator starts, with one line naming what it takes.

Why refuse rather than convert at the entry: a mapping becomes a DatasetConfig in one place, where the
YAML is read (config.validate / load_config, and config.from_record for a stored config.json), so the
checks and the defaults are applied once and every caller is visibly on the model; a silent conversion
at each entry would keep dict-building callers working and hide them.
"""
import os
import re

import pytest

from helpers import small_config

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# the config read as a dict: cfg["x"], cfg['x'], cfg.get("x"), self.cfg[...], assets.cfg[...], config["x"]
DICT_READ = re.compile(r"""\b(?:cfg|config|dataset_cfg|kp_cfg|lod_cfg|labels_cfg)\s*(?:\[\s*["']|\.get\(\s*["'])""")
# the folders whose code receives the DatasetConfig
SCANNED = ("splatting/dataset", "splatting/library/use.py", "splatting/library/dataset_ray.py",
           "splatting/cyclist/appearance.py")


def _python_files():
    for entry in SCANNED:
        path = os.path.join(ROOT, entry)
        if os.path.isfile(path):
            yield path
            continue
        for folder, _, files in os.walk(path):
            yield from (os.path.join(folder, f) for f in sorted(files) if f.endswith(".py"))


def dict_reads(text):
    """(line number, line) of every dict-style read of a config in a module's source."""
    return [(i, line.strip()) for i, line in enumerate(text.splitlines(), 1)
            if DICT_READ.search(line.split("#", 1)[0])]


def test_the_pattern_catches_dict_reads_and_passes_attribute_reads():
    bad = ['x = cfg["street"]["distance_m"]', "n = self.cfg['count']", 'if cfg.get("sequence"):',
           'f"{cfg[\'mode\']}"', 'lo = kp_cfg["person"]', 'names = labels_cfg["names"]']
    good = ["x = cfg.street.distance_m", "n = self.cfg.count  # not cfg[\"count\"]", 'rec["sequence"] = {}',
            'spec = cam["width"]']
    assert all(dict_reads(t) for t in bad)
    assert not any(dict_reads(t) for t in good)


def test_no_dict_reads_of_the_dataset_config():
    found = []
    for path in _python_files():
        with open(path, encoding="utf-8") as f:
            found += [f"{os.path.relpath(path, ROOT)}:{i}: {line}" for i, line in dict_reads(f.read())]
    assert not found, ("the dataset config is a DatasetConfig: read its attributes (cfg.street.distance_m), "
                       "not a dict:\n" + "\n".join(found))


def test_the_generator_refuses_a_plain_dict(tmp_path):
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from splatting.dataset.generate import Assets, config_record, make_sample
    raw = small_config(str(tmp_path), count=1)
    record = config_record(validate(raw))  # a dict, as config.json holds it
    for call in (lambda: generate(record, str(tmp_path / "out"), log=lambda m: None, progress=False),
                 lambda: Assets(record), lambda: make_sample(record, 0, None), lambda: config_record(record)):
        with pytest.raises(TypeError, match="takes a DatasetConfig .* got dict"):
            call()
    assert not os.path.exists(tmp_path / "out")  # refused before any work


def test_the_config_cannot_be_changed_on_its_way_through_the_generator(tmp_path):
    from pydantic import ValidationError
    from splatting.dataset.config import validate
    cfg = validate(small_config(str(tmp_path)))
    for block, field, value in ((cfg, "count", 3), (cfg.street, "distance_m", [1, 2]), (cfg.insert.look, "match", False)):
        with pytest.raises(ValidationError, match="frozen"):
            setattr(block, field, value)
    assert cfg.model_copy(update={"count": 3}).count == 3 and cfg.count == small_config(str(tmp_path))["count"]


def test_a_stored_record_reads_back_as_the_same_config(tmp_path):
    """config.json (generate.config_record) -> config.from_record -> the same record: the merge step and
    a resumed run see the config the generator saw."""
    from splatting.dataset.config import from_record, validate
    from splatting.dataset.generate import config_record
    for extra in ({}, {"lighting": {"mode": "relit"}}, {"sequence": {"still_signal_share": 0.5}},
                  {"mode": "street", "camera": {"preset": "kitti"}, "image_size": 512}):
        cfg = validate(dict(small_config(str(tmp_path)), **extra))
        back = from_record(config_record(cfg))
        assert back == cfg and config_record(back) == config_record(cfg)
    # a resolved bike-only config has no riders (resolve_assets), which a written config may not say
    bike_only = validate(dict(small_config(str(tmp_path)), mode="bike-only")).model_copy(update={"riders": []})
    assert from_record(config_record(bike_only)).riders == [] and from_record(config_record(bike_only)) == bike_only

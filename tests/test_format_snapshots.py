"""Snapshots of the JSON formats (docs/contract.md): the key structure and value types of meta.json,
keypoints.json, cameras.json and a COCO shard, as written by the code today, against the committed
snapshots in tests/snapshots/.  A format change then fails here until the snapshot (and the
contract page) are changed with it, deliberately:

    UPDATE_SNAPSHOTS=1 .venv/bin/python -m pytest tests/test_format_snapshots.py
"""
import json
import os
import re
import subprocess
import sys

import pytest

from helpers import ROOT, SCRIPTS, small_config, write_test_bike, write_yaml

SNAP = os.path.join(os.path.dirname(os.path.abspath(__file__)), "snapshots")
# keys that are names drawn from a family (one camera per view, one image per sample) fold into one
FAMILIES = [(re.compile(r"^camera\d{4}$"), "camera####"), (re.compile(r"^\w+->\w+$"), "<joint>-><target>")]


def shape(v):
    """The structure of a JSON value: dict keys with the shape of their values, one shape per list."""
    if isinstance(v, dict):
        out = {}
        for k in sorted(v):
            key = next((name for pat, name in FAMILIES if pat.match(k)), k)
            out.setdefault(key, shape(v[k]))
        return out
    if isinstance(v, list):
        shapes = []
        for x in v:
            s = shape(x)
            if s not in shapes:
                shapes.append(s)
        return shapes
    if isinstance(v, bool):
        return "bool"
    if isinstance(v, (int, float)):
        return "number"
    return type(v).__name__


def check(name, doc):
    path = os.path.join(SNAP, name)
    got = shape(doc)
    if os.environ.get("UPDATE_SNAPSHOTS"):
        with open(path, "w") as f:
            json.dump(got, f, indent=1, sort_keys=True)
            f.write("\n")
    with open(path) as f:
        want = json.load(f)
    assert got == want, f"{name} changed its format; if deliberate, update docs/contract.md and the snapshot"


def test_shape_sees_a_renamed_key():
    assert shape({"K": [[1.0]], "R": 1}) != shape({"K": [[1.0]], "Rot": 1})
    assert shape({"camera0000": {"K": 1}, "camera0001": {"K": 2}}) == {"camera####": {"K": "number"}}


def test_cameras_json():
    from cyclist_formats import ring
    check("cameras.json", ring.ring([0.0, 0.5, 0.0]))


@pytest.fixture(scope="module")
def generated_bike(tmp_path_factory):
    out = tmp_path_factory.mktemp("snap")
    r = subprocess.run([sys.executable, os.path.join(SCRIPTS, "make_bikes.py"), "--out", str(out), "--count", "1",
                        "--seed", "0"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    bikes = [os.path.join(out, "bikes", b) for b in sorted(os.listdir(os.path.join(out, "bikes")))]
    with_crank = [b for b in bikes if json.load(open(os.path.join(b, "meta.json")))["has_crank"]]
    assert with_crank, bikes
    return with_crank[0]  # a bicycle: the richest meta.json and all 11 keypoints


def test_meta_json(generated_bike):
    with open(os.path.join(generated_bike, "meta.json")) as f:
        check("meta.json", json.load(f))


def test_keypoints_json(generated_bike):
    with open(os.path.join(generated_bike, "keypoints.json")) as f:
        check("keypoints.json", json.load(f))


def test_coco_shard(tmp_path):
    bikes = tmp_path / "bikes"
    write_test_bike(str(bikes))
    cfg = write_yaml(tmp_path / "c.yaml", small_config(str(bikes), count=1, image_size=32))
    out = tmp_path / "ds"
    r = subprocess.run([sys.executable, "-m", "splatting", "dataset", "--config", str(cfg), "--out", str(out)],
                       capture_output=True, text=True, cwd=ROOT, env=dict(os.environ, OMP_NUM_THREADS="1"), timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    with open(out / "annotations.json") as f:
        coco = json.load(f)
    check("coco_annotations.json", coco)

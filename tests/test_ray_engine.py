"""Datasets on Ray (issue 15): the same bytes as one process, whether run as Ray tasks, as N
`--shard K/N` processes + `dataset merge`, or after a Ray worker or the driver was killed mid-run.

One local Ray cluster per test session (`ray.init(num_cpus=2)`, a few seconds to start).
"""
import os
import signal
import subprocess
import sys
import time

import pytest

from helpers import ROOT, small_config, write_test_bike, write_yaml

ray = pytest.importorskip("ray")


@pytest.fixture(scope="session")
def ray_cluster():
    from splatting.library.engine import ray_runtime_env
    ray.init(num_cpus=2, runtime_env=ray_runtime_env(), include_dashboard=False, log_to_driver=False)
    yield ray.get_runtime_context().gcs_address
    ray.shutdown()


def _one_process_dataset(tmp_path_factory, count):
    """(root, config, out) of a one-process bike-only dataset of `count` samples: the reference
    every other way of running must reproduce byte for byte."""
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    root = tmp_path_factory.mktemp("ray_ds")
    write_test_bike(str(root))
    # bike-only: no rider body to build in every worker process, so the tests stay short
    cfg = small_config(str(root), count=count, mode="bike-only")
    out = str(root / "one_process")
    generate(validate(cfg), out, log=lambda m: None, progress=False)
    return root, cfg, out


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return _one_process_dataset(tmp_path_factory, 6)


@pytest.fixture(scope="module")
def reference_long(tmp_path_factory):
    """Enough samples that a Ray worker is still busy after the first shard is written: 6 bike-only
    64 px samples took the whole Ray run under 0.2 s on a quiet machine, so the kill tests found no
    busy worker to kill, or a driver killed after it had finished."""
    return _one_process_dataset(tmp_path_factory, 120)


def same_dataset(a, b):
    with open(os.path.join(a, "annotations.json"), "rb") as fa, open(os.path.join(b, "annotations.json"), "rb") as fb:
        assert fa.read() == fb.read(), "annotations differ"
    ia = sorted(f for f in os.listdir(os.path.join(a, "images")) if not f.startswith("."))
    assert ia == sorted(f for f in os.listdir(os.path.join(b, "images")) if not f.startswith("."))
    for f in ia:
        with open(os.path.join(a, "images", f), "rb") as fa, open(os.path.join(b, "images", f), "rb") as fb:
            assert fa.read() == fb.read(), f


def cli(*argv):
    return subprocess.run([sys.executable, "-m", "splatting", *argv], cwd=ROOT, capture_output=True, text=True,
                          env=dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=ROOT))


def test_ray_engine_matches_one_process(reference, ray_cluster, tmp_path):
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    _, cfg, ref = reference
    out = str(tmp_path / "ray")
    r = generate(validate(cfg), out, log=lambda m: None, progress=False, engine="ray")
    assert r["generated"] == cfg["count"]
    same_dataset(ref, out)


def test_shards_then_merge_match_one_process(reference, tmp_path):
    _, cfg, ref = reference
    path = write_yaml(str(tmp_path / "c.yaml"), cfg)
    out = str(tmp_path / "sharded")
    procs = [subprocess.Popen([sys.executable, "-m", "splatting", "dataset", "--config", path, "--out", out,
                               "--shard", f"{k}/2", "--quiet"], cwd=ROOT, env=dict(os.environ, OMP_NUM_THREADS="1"),
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for k in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=600)
        assert p.returncode == 0, err
    assert not os.path.exists(os.path.join(out, "annotations.json"))  # shards never merge
    shards = sorted(os.listdir(os.path.join(out, "shards")))
    assert len(shards) == cfg["count"]
    r = cli("dataset", "merge", "--out", out)
    assert r.returncode == 0, r.stderr
    same_dataset(ref, out)
    first = open(os.path.join(out, "annotations.json"), "rb").read()
    assert cli("dataset", "merge", "--out", out).returncode == 0  # idempotent
    assert open(os.path.join(out, "annotations.json"), "rb").read() == first


def test_merge_refuses_missing_samples(reference, tmp_path):
    _, cfg, _ = reference
    path = write_yaml(str(tmp_path / "c.yaml"), dict(cfg, count=3))
    out = str(tmp_path / "partial")
    r = cli("dataset", "--config", path, "--out", out, "--shard", "0/2", "--quiet")
    assert r.returncode == 0, r.stderr
    r = cli("dataset", "merge", "--out", out)
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1
    assert "1 of 3 samples are not generated" in r.stderr
    assert not os.path.exists(os.path.join(out, "annotations.json"))


def _render_range_pids():
    """Ray worker processes busy in a dataset task (Ray names them after the task)."""
    pids = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                cmd = f.read()
        except OSError:
            continue
        if b"ray::_render_range" in cmd:
            pids.append(int(pid))
    return pids


def _shards(out):
    d = os.path.join(out, "shards")
    return len([f for f in os.listdir(d) if f.endswith(".json") and not f.startswith(".")]) if os.path.isdir(d) else 0


def test_killed_ray_worker_is_retried(reference_long, ray_cluster, tmp_path):
    import threading

    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    _, cfg, ref = reference_long
    out = str(tmp_path / "worker_killed")
    res = {}
    th = threading.Thread(target=lambda: res.update(generate(validate(cfg), out, log=lambda m: None, progress=False,
                                                             engine="ray")))
    th.start()
    killed, t0 = [], time.time()
    while not killed and th.is_alive() and time.time() - t0 < 300:
        pids = _render_range_pids()
        if pids and _shards(out) >= 1:
            os.kill(pids[0], signal.SIGKILL)
            killed.append(pids[0])
        time.sleep(0.01)
    th.join(600)
    assert killed, "no busy Ray worker was found to kill"
    assert _shards(out) == cfg["count"] and res.get("annotations")
    same_dataset(ref, out)


def test_killed_driver_then_rerun(reference_long, ray_cluster, tmp_path):
    _, cfg, ref = reference_long
    path = write_yaml(str(tmp_path / "c.yaml"), cfg)
    out = str(tmp_path / "driver_killed")
    argv = [sys.executable, "-m", "splatting", "dataset", "--config", path, "--out", out, "--engine", "ray",
            "--address", ray_cluster, "--quiet"]
    p = subprocess.Popen(argv, cwd=ROOT, env=dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=ROOT),
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.time()
    while p.poll() is None and time.time() - t0 < 300 and _shards(out) < 2:
        time.sleep(0.05)
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert not os.path.exists(os.path.join(out, "annotations.json")), "killed too late to test resuming"
    r = subprocess.run(argv[:-1], cwd=ROOT, env=dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=ROOT),
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "already done" in r.stdout
    same_dataset(ref, out)


def test_ray_engine_runs_sequences_by_sequence(ray_cluster, tmp_path):
    """Sequences on Ray: one task per sequence, the same bytes as one process (parked bikes only:
    no rider body to build in every worker)."""
    from helpers import street_config
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from splatting.library.dataset_ray import by_sequence
    assert by_sequence([0, 1, 2, 4, 5, 7], 3) == [[0, 1, 2], [4, 5], [7]]
    write_test_bike(str(tmp_path))
    cfg = validate(street_config(str(tmp_path), count=2, labels={"formats": ["coco", "kitti", "mot"]},
                                 street={"cyclists": [0, 0], "parked_bikes": [2, 2]},
                                 sequence={"enabled": True, "length": 3}))
    a, b = str(tmp_path / "one"), str(tmp_path / "ray")
    generate(cfg, a, log=lambda m: None, progress=False)
    r = generate(cfg, b, log=lambda m: None, progress=False, engine="ray")
    assert r["generated"] == 6
    for rel in ["annotations.json", "kitti_tracking/training/label_02/0001.txt", "mot/0000/gt/gt.txt"] + \
            [f"images/{s:04d}/{f:06d}.png" for s in range(2) for f in range(3)]:
        with open(os.path.join(a, rel), "rb") as fa, open(os.path.join(b, rel), "rb") as fb:
            assert fa.read() == fb.read(), rel

"""Scale-out benchmarks (issue 15): the library build with 1 and 2 workers, and the dataset on
Ray against the local process pool.

Keys:
  library_build_s      {workers_1, workers_2, speedup, efficiency, bikes, tasks, per_task_s}: wall time of
                       `library build` for a fixed small library (2 procedural bikes, views at
                       64 px / 4 samples, 200 iterations and 3000 Gaussians per part, 2 ground-truth
                       poses) from scratch, --workers 1 then --workers 2; per_task_s = median task
                       wall times by kind (views s/view, part training s, ground truth s), the
                       inputs of docs/scale_out.md's cost model.
  dataset_images_per_hour_local / _ray: the same bike-only config (stand-in Gaussians, 256 px),
                       160 images, 2 local workers vs a 2-CPU local Ray cluster already running; medians of 3
                       interleaved runs.
  dataset_ray_overhead 1 - Ray rate / local rate (goal < 0.1); dataset_ray_start_s: starting the
                       local cluster (paid once per run, not per image).
Run alone: `python -m bench.library [--out DIR] [--skip-library]`.
"""
import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

# without the posed fine-tune (added to the library later): the same 10 tasks as the recorded numbers
BUDGET = ["--size", "64", "--samples", "4", "--iterations", "200", "--max-gaussians", "3000", "--gt-poses", "2",
          "--no-posed-train", "--quiet"]


def _env():
    return dict(os.environ, OMP_NUM_THREADS="1", OMP_WAIT_POLICY="PASSIVE",
                PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))


def library_build(results, out_dir):
    base = os.path.join(out_dir, "library_bench")
    seed = os.path.join(base, "seed")
    if not os.path.isdir(os.path.join(seed, "bikes")):
        subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "make_bikes.py"), "--out", seed,
                        "--count", "2", "--no-extras"], check=True, cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL)
    times, per_kind = {}, {}
    for w in (1, 2):
        d = os.path.join(base, f"workers_{w}")
        shutil.rmtree(d, ignore_errors=True)
        shutil.copytree(seed, d)
        t = time.time()
        subprocess.run([sys.executable, "-m", "splatting", "library", "build", "--out", d, "--workers", str(w), *BUDGET],
                       check=True, cwd=ROOT, env=_env())
        times[w] = time.time() - t
        print(f"  library_build: {w} worker(s) {times[w]:.1f} s", flush=True)
        tasks = os.path.join(d, "library", "tasks")
        for f in sorted(os.listdir(tasks)):
            with open(os.path.join(tasks, f)) as fh:
                rec = json.load(fh)
            kind = rec["task"].split(":")[0]
            per_kind.setdefault(kind, []).append(rec["metrics"].get("s_per_view") if kind == "views" else rec["wall_s"])
    n_tasks = len(os.listdir(os.path.join(base, "workers_1", "library", "tasks")))
    results["library_build_s"] = {
        "workers_1": round(times[1], 1), "workers_2": round(times[2], 1), "speedup": round(times[1] / times[2], 3),
        "efficiency": round(times[1] / (2 * times[2]), 3), "bikes": 2, "tasks": n_tasks,
        "per_task_s": {("views_s_per_view" if k == "views" else f"{k}_s"): round(statistics.median(v), 3)
                       for k, v in per_kind.items()},
        "budget": " ".join(BUDGET[:-1])}


def _dataset_config(root, count):
    from bench.dataset import _write_spec_bike
    bike = _write_spec_bike(root)  # keypoints + meta of a procedural city bike: stand-in Gaussians
    return {"name": "ray_bench", "mode": "bike-only", "seed": 0, "count": count, "image_size": 256,
            "bikes": [bike], "bikes_root": root, "synthetic_assets": "always", "synthetic_gaussians_per_part": 3000,
            "png_compress_level": 4}


def dataset_overhead(results, out_dir, count=160, rounds=3):
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from splatting.library.engine import ensure_ray

    base = os.path.join(out_dir, "ray_bench")
    shutil.rmtree(base, ignore_errors=True)
    os.makedirs(base)
    cfg = validate(_dataset_config(base, count))
    t = time.time()
    ray = ensure_ray(None, num_cpus=2)
    results["dataset_ray_start_s"] = round(time.time() - t, 2)
    rates = {"local": [], "ray": []}
    try:
        for k in range(rounds):  # interleaved: the shared machine's load drifts
            for engine in ("local", "ray"):
                out = os.path.join(base, f"{engine}_{k}")
                t = time.time()
                generate(cfg, out, workers=2, log=lambda m: None, progress=False, engine=engine)
                rates[engine].append(count / (time.time() - t) * 3600)
                print(f"  dataset {engine}: {rates[engine][-1]:.0f} images/h", flush=True)
        with open(os.path.join(base, "local_0", "annotations.json"), "rb") as a, \
                open(os.path.join(base, "ray_0", "annotations.json"), "rb") as b:
            same = a.read() == b.read()
    finally:
        ray.shutdown()
    loc, ry = statistics.median(rates["local"]), statistics.median(rates["ray"])
    results["dataset_images_per_hour_local"] = round(loc)
    results["dataset_images_per_hour_ray"] = round(ry)
    results["dataset_ray_overhead"] = round(1 - ry / loc, 4)
    results["dataset_ray_bench"] = {"count": count, "image_size": 256, "mode": "bike-only (stand-ins)", "cpus": 2,
                                    "rounds": rounds, "identical_annotations": same}


def run(results, out_dir, skip_library=False):
    if not skip_library:
        library_build(results, out_dir)
    dataset_overhead(results, out_dir)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
    ap.add_argument("--skip-library", action="store_true")
    a = ap.parse_args()
    res = {}
    run(res, a.out, a.skip_library)
    print(json.dumps(res, indent=1))

"""Street-scene throughput benchmark (issue 12).

Key: `street_images_per_hour` = street images per hour written by `dataset` with 2 worker
processes (one torch thread each): the street preset's scene (1-6 cyclists, up to one parked bike,
3-60 m) on the nuScenes CAM_FRONT camera (1600x900), photo backgrounds (JPGs made here, 1920x1080,
scaled and cropped per sample), COCO annotations (visible + amodal RLE masks, 17 + 11 keypoints,
3D fields) written; from start to the finished annotations.json (worker start-up and asset
loading included).  Goal >= 3000/h on 2 cores.
`street_images_per_hour_projected_2_cores` = 2 x 3600 / the median CPU seconds per image of one
in-process worker: a PROJECTION (it assumes two unshared cores scale perfectly), not a measured rate;
the wall-clock key is the measured one (it depends on what else the machine runs).
Also `street_bench`: the per-image median of one worker's samples, split into posing (IK + LBS),
rendering (one joint rasterization + the amodal ones) and the rest (labels, PNG, files), measured
in-process on the same config.  Assets as in bench.dataset: trained ones where they exist, else
stand-ins (said in the results).  Run alone: `python -m bench.street [--out DIR] [--count N]`.
"""
import json
import os
import shutil
import statistics
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench import bench_parser  # noqa: E402

RIDER = "m_adult_average_185"


def write_photos(folder, n=4, size=(1920, 1080)):
    """A few photo-sized JPGs (value noise: no download) for the `images` background."""
    import numpy as np
    from PIL import Image
    from splatting.dataset.backgrounds import generated
    os.makedirs(folder, exist_ok=True)
    for i in range(n):
        img = (generated("noise", 100 + i, *size) * 255).astype(np.uint8)
        Image.fromarray(img).save(os.path.join(folder, f"street_{i}.jpg"), quality=90)
    return folder


def avatar_trained():
    return os.path.isfile(os.path.join(ROOT, "data", "riders", RIDER, "skinning.npz"))


def bench_config(scratch, out_dir, count):
    from bench.dataset import pick_assets
    from splatting.dataset.config import load_yaml, preset_path
    bikes_root, bikes, synth, desc = pick_assets(out_dir, scratch)
    if synth == "never" and not avatar_trained():
        synth = "auto"  # trained bikes, but the rider is the mesh avatar (said in the results)
    cfg = load_yaml(preset_path("street"))
    cfg.update(name="bench_street", count=count, bikes=bikes, bikes_root=bikes_root, synthetic_assets=synth,
               riders=[RIDER], riders_root=os.path.join(ROOT, "data", "riders"))
    cfg["camera"] = {"preset": "nuscenes"}
    cfg["street"] = dict(cfg.get("street", {}), cyclists=[1, 6])
    cfg["backgrounds"] = {"kinds": ["images"], "images_dir": write_photos(os.path.join(scratch, "photos"))}
    cfg["labels"] = {"formats": ["coco"]}
    return cfg, desc


def split_timings(cfg, n):
    """Median seconds per image of one in-process worker, split by stage (wrapped functions)."""
    import torch
    torch.set_num_threads(1)
    from splatting.dataset import generate as G
    from splatting.dataset.config import resolve_assets, validate
    cfg = resolve_assets(validate(cfg))
    assets = G.Assets(cfg)
    spent = {"pose": 0.0, "render": 0.0}
    orig_render = G.render_scene

    def timed_render(*a, **k):
        t = time.perf_counter()
        try:
            return orig_render(*a, **k)
        finally:
            spent["render"] += time.perf_counter() - t
    G.render_scene = timed_render
    from splatting.cyclist.compose import Cyclist
    orig_pose = Cyclist.pose

    def timed_pose(self, *a, **k):
        t = time.perf_counter()
        try:
            return orig_pose(self, *a, **k)
        finally:
            spent["pose"] += time.perf_counter() - t
    Cyclist.pose = timed_pose
    rows = []
    scratch = tempfile.mkdtemp(prefix="bench_street_split_")
    try:
        G.write_sample(cfg, cfg.count - 1, scratch, assets)  # load assets outside the timing
        for i in range(n):
            spent.update(pose=0.0, render=0.0)
            t, c = time.perf_counter(), time.process_time()
            G.write_sample(cfg, i, scratch, assets)
            total, cpu = time.perf_counter() - t, time.process_time() - c
            rows.append((total, spent["pose"], spent["render"], total - spent["pose"] - spent["render"], cpu))
    finally:
        G.render_scene, Cyclist.pose = orig_render, orig_pose
        shutil.rmtree(scratch, ignore_errors=True)
    med = lambda k: round(statistics.median(r[k] for r in rows), 3)  # noqa: E731
    return {"total_s": med(0), "pose_s": med(1), "render_s": med(2), "rest_s": med(3), "cpu_s": med(4), "images": n}


def run(results, out_dir, count=12):
    import torch
    torch.set_num_threads(1)
    from bench.dataset import timed_generate
    scratch = tempfile.mkdtemp(prefix="bench_street_")
    try:
        cfg, desc = bench_config(scratch, out_dir, count)
        avatar = "trained avatar" if avatar_trained() else "untrained mesh avatar"
        print(f"street bench: bikes: {desc}; rider {RIDER}: {avatar}")
        out = os.path.join(scratch, "out")
        doc, wall, load = timed_generate(cfg, out, workers=2)
        n_inst = sum(len(im["instances"]) for im in doc["images"])
        iph = count * 3600.0 / wall
        print(f"street bench: {count} images 1600x900 ({n_inst} instances, {len(doc['annotations'])} annotations) "
              f"with 2 workers in {wall:.1f} s -> {iph:.0f} images/hour (goal >= 3000; 1-min load average "
              f"{load[0]} before, {load[1]} after: the cores are shared)")
        split = split_timings(dict(cfg, count=count), max(3, count // 3))
        print(f"street bench: 1 worker, median per image {split['total_s']} s = posing {split['pose_s']} + "
              f"rendering {split['render_s']} + labels/files {split['rest_s']}")
        # CPU seconds per image (one torch thread: process time = core time): what two unshared
        # cores would give, as the wall clock on this shared machine cannot say
        cpu_iph = 2 * 3600.0 / split["cpu_s"]
        print(f"street bench: {split['cpu_s']} CPU s per image (median) -> {cpu_iph:.0f} images/hour on 2 unshared cores")
        results["street_images_per_hour"] = round(iph, 1)
        results["street_images_per_hour_projected_2_cores"] = round(cpu_iph, 1)
        from bench.provenance import record
        record(results, "street_images_per_hour", "fresh", kind="measured (wall clock, 2 worker processes)", bikes=desc,
               rider=avatar)
        record(results, "street_images_per_hour_projected_2_cores", "fresh",
               kind="projection: 2 x 3600 / median CPU s per image of one worker (assumes perfect 2-core scaling)")
        results["street_bench"] = {"images": count, "workers": 2, "wall_s": round(wall, 2), "instances": n_inst,
                                   "camera": "nuscenes 1600x900", "bikes": desc, "rider": avatar,
                                   "lod": cfg["lod"]["enabled"], "appearance": cfg["appearance"]["enabled"],
                                   "load_avg_1m_before_after": load, "cpu_count": os.cpu_count(),
                                   "one_worker_split": split}
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return results


def main(argv=None):
    ap = bench_parser("street", __doc__)
    ap.add_argument("--count", type=int, default=12)
    args = ap.parse_args(argv)
    results = {}
    run(results, args.out, args.count)
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

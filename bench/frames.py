"""Cyclists inserted into KITTI frames (issue 26, docs/kitti_insert.md): throughput and geometry.

Keys:
- `frames_images_per_hour` / `frames_images_per_hour_lidar`: augmented frames per hour written by
  `dataset` (the kitti-insert preset, one worker process with one torch thread, COCO + KITTI files)
  on the development frames without / with their LiDAR (with: placement checks against the scan,
  its depth image as an occluder, the cyclists ray-cast into velodyne/), from start to the finished
  annotations.json (asset loading included): count x 3600 / wall seconds.
- `frames_geometry`: over every inserted instance of the LiDAR run: the share whose two tyres'
  lowest points are within 3 cm of the road plane (the posed rims, frames.contact), the median and
  largest |height above the plane| of the KITTI box's bottom centre (the lowest posed Gaussian:
  independent of the rim maths), and the number of inserted 3D box footprints overlapping a
  labelled box's footprint (goal 0).
- `frames_look`: the image gradient energy (mean squared luminance gradient over the box's luminance
  variance: sharpness free of contrast) and noise sigma (Immerkaer, grey levels) inside the inserted,
  unoccluded, untruncated cyclists' 2D boxes against the frames' own unoccluded pedestrians and
  cyclists, medians (and their box heights).
- `frames_label_stats`: the inserted Cyclist rows against SOURCES.md's KITTI figures: 2D box
  height median and 5th-95th percentiles (px), distance z median and 5th-95th (m), occluded and
  truncated shares.
Assets: the demo's trained bike and rider (out/demo) when present, else keypoint stand-ins (said).
Run alone: `python -m bench.frames [--frames DIR] [--count N] [--out DIR]`.
"""
import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

RIDER = "m_adult_average_185"
DEV = next((p for p in (os.path.join(ROOT, "..", "shared", "realism", "kitti_dev"),
                        os.path.join(ROOT, "..", "..", "shared", "realism", "kitti_dev")) if os.path.isdir(p)), None)


def demo_assets(demo_dir=None):
    """(bikes_root, bikes, riders_root, synthetic, description) of the demo's trained assets, else None."""
    for demo in [demo_dir or os.path.join(ROOT, "out", "demo")]:
        bikes = os.path.join(demo, "bikes")
        riders = os.path.join(demo, "riders")
        if os.path.isfile(os.path.join(riders, RIDER, "skinning.npz")) and os.path.isdir(bikes):
            ok = sorted(b for b in os.listdir(bikes) if os.path.isfile(os.path.join(bikes, b, "gaussians", "frame.ply")))
            if ok:
                return bikes, ok[:1], riders, "never", f"trained: bike {ok[0]} and rider {RIDER} of {os.path.abspath(demo)}"
    return None


def config(frames, count, lidar, assets, scratch):
    from splatting.dataset.config import load_yaml, preset_path
    cfg = load_yaml(preset_path("kitti-insert"))
    cfg.update(frames=os.path.abspath(frames), count=count, labels={"formats": ["coco", "kitti"]})
    cfg["insert"] = dict(cfg.get("insert") or {}, lidar=lidar)
    if assets is None:
        sys.path.insert(0, os.path.join(ROOT, "tests"))
        from helpers import write_test_bike
        write_test_bike(scratch)
        cfg.update(bikes_root=scratch, bikes=["city_t"], riders=[RIDER], riders_root=os.path.join(scratch, "none"),
                   synthetic_assets="always", rider_gaussians=2500)
    else:
        cfg.update(bikes_root=assets[0], bikes=assets[1], riders=[RIDER], riders_root=assets[2], synthetic_assets=assets[3])
    return cfg


def geometry(out, frames):
    from cyclist_formats.kitti_frame import check_folder, parse_labels
    from splatting.dataset.frames.road import convex_overlap
    from splatting.dataset.kitti import corners
    with open(os.path.join(out, "annotations.json")) as f:
        doc = json.load(f)
    src = check_folder(frames)
    tyres, bottoms, overlaps, rows = [], [], 0, []
    for im in doc["images"]:
        i = im["id"] - 1
        fr = src[im["frame"]["frame"]]
        for rec in im["instances"]:
            tyres.append(max(abs(x) for x in rec["tyre_heights_m"]))
        labels = [r for r, _ in parse_labels(os.path.join(out, "kitti", "training", "label_2", f"{i:06d}.txt"))]
        own = [r for r, _ in fr["labels"] if r["type"] != "DontCare"]
        new = labels[len(fr["labels"]):]
        a, b, c, d = fr["plane"] if fr["plane"] is not None else im["frame"]["plane"]
        for r in new:
            rows.append(r)
            bottoms.append(abs(a * r["x"] + b * r["y"] + c * r["z"] + d))
            fp = corners(r["h"], r["w"], r["l"], (r["x"], r["y"], r["z"]), r["rotation_y"])[[0, 2], :4].T
            for o in own:
                fo = corners(o["h"], o["w"], o["l"], (o["x"], o["y"], o["z"]), o["rotation_y"])[[0, 2], :4].T
                overlaps += int(convex_overlap(fp, fo))
    cyc = [r for r in rows if r["type"] == "Cyclist"]
    hpx = [r["y2"] - r["y1"] for r in cyc]
    zs = [r["z"] for r in cyc]
    pct = lambda v: [round(float(x), 1) for x in np.percentile(v, [5, 50, 95])] if v else None  # noqa: E731
    geo = {"instances": len(tyres), "tyres_within_3cm_share": round(sum(t <= 0.03 for t in tyres) / max(len(tyres), 1), 4),
           "tyre_height_max_m": round(max(tyres), 4) if tyres else None,
           "box_bottom_height_median_m": round(statistics.median(bottoms), 4) if bottoms else None,
           "box_bottom_height_max_m": round(max(bottoms), 4) if bottoms else None,
           "labelled_box_overlaps": overlaps}
    stats = {"cyclist_rows": len(cyc), "box_height_px_p5_p50_p95": pct(hpx), "distance_m_p5_p50_p95": pct(zs),
             "occluded_share": round(sum(r["occluded"] >= 1 for r in cyc) / max(len(cyc), 1), 3),
             "truncated_share": round(sum(r["truncated"] > 0.1 for r in cyc) / max(len(cyc), 1), 3),
             "kitti_reference": "h 60 px median (24-198), z 18 m (6-41), 36 % occluded, ~4 % truncated (SOURCES.md)"}
    return geo, stats


def _box_look(img, r):
    """(normalised gradient energy, noise sigma in grey levels) of a uint8 image inside a label's 2D box."""
    from splatting.dataset.frames.look import LUMA, estimate_noise
    x1, y1, x2, y2 = int(r["x1"]), int(r["y1"]), int(r["x2"]) + 1, int(r["y2"]) + 1
    crop = img[y1:y2, x1:x2]
    g = crop.astype(np.float64) @ LUMA
    gx, gy = np.diff(g, axis=1)[:-1], np.diff(g, axis=0)[:, :-1]
    energy = float(((gx ** 2 + gy ** 2).mean()) / max(g.var(), 1e-9))  # contrast-free: sharpness, not brightness
    return energy, estimate_noise(crop) * 255.0


def look_stats(out, frames, min_px=30):
    """Gradient energy and noise inside the inserted cyclists' boxes against the frames' own unoccluded
    pedestrians and cyclists (boxes at least min_px tall), medians."""
    from cyclist_formats.kitti_frame import check_folder, parse_labels
    from splatting.dataset.frames.source import read_image
    with open(os.path.join(out, "annotations.json")) as f:
        doc = json.load(f)
    src = check_folder(frames)
    ins, real, hins, hreal = [], [], [], []
    for im in doc["images"]:
        i = im["id"] - 1
        img = read_image(os.path.join(out, "images", im["file_name"]))
        rows = [r for r, _ in parse_labels(os.path.join(out, "kitti", "training", "label_2", f"{i:06d}.txt"))]
        for r in rows[len(im["frame"]["occlusion_raised"]):]:
            if r["type"] == "Cyclist" and r["occluded"] == 0 and r["truncated"] < 0.05 and r["y2"] - r["y1"] >= min_px:
                ins.append(_box_look(img, r))
                hins.append(r["y2"] - r["y1"])
    for fid, fr in src.items():
        img = read_image(fr["image"])
        for r, _ in fr["labels"]:
            if r["type"] in ("Pedestrian", "Cyclist") and r["occluded"] == 0 and r["y2"] - r["y1"] >= min_px:
                real.append(_box_look(img, r))
                hreal.append(r["y2"] - r["y1"])
    med = lambda v, k: round(float(np.median([x[k] for x in v])), 4) if v else None  # noqa: E731
    return {"inserted": {"n": len(ins), "height_px_median": round(float(np.median(hins)), 1) if hins else None,
                         "grad_energy_median": med(ins, 0), "noise_grey_median": med(ins, 1)},
            "real_people": {"n": len(real), "height_px_median": round(float(np.median(hreal)), 1) if hreal else None,
                            "grad_energy_median": med(real, 0), "noise_grey_median": med(real, 1)}}


def measure(cfg, scratch, tag):
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    out = os.path.join(scratch, tag)
    t = time.time()
    generate(validate(cfg), out, workers=1, log=lambda m: None, progress=False)
    return out, time.time() - t


def run(results, out_dir=None, frames=None, count=10, keep=None, demo=None):
    frames = frames or DEV
    if frames is None:
        print("bench frames: skipped (no ../shared/realism/kitti_dev)")
        return
    import torch
    torch.set_num_threads(1)
    scratch = tempfile.mkdtemp(prefix="bench_frames_")
    try:
        assets = demo_assets(demo)
        walls = {}
        for lidar in (False, True):
            cfg = config(frames, count, lidar, assets, scratch)
            out, walls[lidar] = measure(cfg, scratch, f"lidar_{lidar}")
        results["frames_images_per_hour"] = round(count * 3600.0 / walls[False], 1)
        results["frames_images_per_hour_lidar"] = round(count * 3600.0 / walls[True], 1)
        geo, stats = geometry(out, frames)
        geo["assets"] = assets[4] if assets else "SYNTHETIC keypoint stand-ins (no trained demo assets)"
        geo["load"] = f"{os.getloadavg()[0]:.1f} (1-min load average at the end, {os.cpu_count()} cores)"
        results["frames_geometry"] = geo
        results["frames_label_stats"] = stats
        results["frames_look"] = look_stats(out, frames)
        if keep:
            shutil.copytree(out, keep, dirs_exist_ok=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.frames", description=__doc__.splitlines()[0])
    ap.add_argument("--frames", default=DEV, help="KITTI object folder (default ../shared/realism/kitti_dev)")
    ap.add_argument("--count", type=int, default=10)
    ap.add_argument("--keep", help="copy the LiDAR run's dataset here")
    ap.add_argument("--demo", help="the demo's output folder with its trained bike and rider (default out/demo)")
    args = ap.parse_args(argv)
    res = {}
    run(res, frames=args.frames, count=args.count, keep=args.keep, demo=args.demo)
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()

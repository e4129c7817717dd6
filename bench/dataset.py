"""Dataset throughput benchmark (issue 7).

Key: `dataset_images_per_hour` = cyclist images (512², RGB + COCO annotations: RLE masks, boxes,
keypoints with visibility) per hour with 2 worker processes (one torch thread each) on this
machine's 2 cores, measured on a short `dataset` run from start to finished annotations.json
(worker start-up and asset loading included).  Bikes: trained part Gaussians from
out_dir/bikes/*/gaussians where they exist, else keypoint stand-ins (printed, and stored under
`dataset_bench` so the report says which); rider: a trained avatar from data/riders/ID if built,
else the untrained mesh avatar.
Chart (out_dir/dataset_throughput.png): images/hour (1 worker) against image size and against
the Gaussian count.  Run alone: `python -m bench.dataset [--out DIR] [--count N] [--no-chart]`.
"""
import json
import os
import shutil
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench import bench_parser  # noqa: E402

RIDER = "m_adult_average_185"


def _trained_bikes(root):
    if not os.path.isdir(root):
        return []
    return sorted(b for b in os.listdir(root)
                  if os.path.isfile(os.path.join(root, b, "gaussians", "frame.ply"))
                  and os.path.isfile(os.path.join(root, b, "keypoints.json")))


def _keypoint_bikes(root):
    from cyclist_formats.bike_folder import has_crank
    if not os.path.isdir(root):
        return []
    return sorted(b for b in os.listdir(root) if os.path.isfile(os.path.join(root, b, "keypoints.json"))
                  and has_crank(os.path.join(root, b)))


def _write_spec_bike(root, style="city", number=0):
    """No library on disk: a bike folder (keypoints + meta) from the procedural generator's spec."""
    from addon.core.procedural import layout, spec
    s = spec.sample_spec(style, number, 0)
    d = os.path.join(root, f"{style}_{number:02d}")
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "keypoints.json"), "w") as f:
        json.dump({"frame": "canonical", "units": "m", "keypoints": {k: list(map(float, v)) for k, v in layout.keypoints(s).items()}}, f)
    with open(os.path.join(d, "meta.json"), "w") as f:
        json.dump({"bike_id": os.path.basename(d), "has_crank": True}, f)
    return os.path.basename(d)


def pick_assets(out_dir, scratch):
    """(bikes_root, bikes, synthetic mode, description)."""
    root = os.path.join(out_dir, "bikes")
    trained = _trained_bikes(root)
    if trained:
        return root, trained, "never", f"trained part Gaussians of {len(trained)} bikes in {root}"
    for r in (root, os.path.join(ROOT, "out", "bikes")):
        kb = _keypoint_bikes(r)
        if kb:
            return r, kb, "auto", f"SYNTHETIC keypoint stand-in Gaussians (no trained bikes in {root}) on {len(kb)} bikes of {r}"
    b = _write_spec_bike(scratch)
    return scratch, [b], "auto", "SYNTHETIC keypoint stand-in Gaussians on a generated spec bike (no bike library)"


def timed_generate(cfg, out, workers):
    """Generate the dataset `cfg` into `out`; returns its annotations.json, the wall seconds and the
    1-minute load average before and after (the cores are shared, so a timing says its load)."""
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    load0 = os.getloadavg()[0]
    t = time.time()
    generate(validate(cfg), out, workers=workers, log=lambda m: None, progress=False)
    wall = time.time() - t
    load = [round(load0, 2), round(os.getloadavg()[0], 2)]
    with open(os.path.join(out, "annotations.json")) as f:
        doc = json.load(f)
    return doc, wall, load


def measure(cfg, workers, scratch, tag):
    out = os.path.join(scratch, tag)
    doc, wall, _ = timed_generate(cfg, out, workers)
    shutil.rmtree(out, ignore_errors=True)
    return cfg["count"] * 3600.0 / wall, wall, len(doc["annotations"])


def gaussian_count(cfg):
    from splatting.dataset.generate import Assets
    a = Assets(cfg)
    c = a.cyclist(cfg.bikes[0], cfg.riders[0])
    return len(c.ids)


def run(results, out_dir, count=24, chart=True):
    import torch
    torch.set_num_threads(1)
    scratch = tempfile.mkdtemp(prefix="bench_dataset_")
    try:
        bikes_root, bikes, synth, desc = pick_assets(out_dir, scratch)
        avatar_kind = "trained avatar" if os.path.isfile(os.path.join(ROOT, "data", "riders", RIDER, "skinning.npz")) \
            else "untrained mesh avatar"
        print(f"dataset bench: bikes: {desc}; rider {RIDER}: {avatar_kind}")
        base = {"name": "bench", "mode": "cyclist", "seed": 0, "count": count, "image_size": 512, "riders": [RIDER],
                "bikes": bikes, "bikes_root": bikes_root, "riders_root": os.path.join(ROOT, "data", "riders"),
                "synthetic_assets": synth}
        from splatting.dataset.config import resolve_assets, validate
        n_g = gaussian_count(resolve_assets(validate(base)))
        iph, wall, n_ann = measure(base, 2, scratch, "main")
        print(f"dataset bench: {count} images 512² ({n_ann} annotations, ~{n_g} Gaussians per cyclist) with 2 workers "
              f"in {wall:.1f} s -> {iph:.0f} images/hour (goal >= 60000, issue 14; shared cores, noisy)")
        results["dataset_images_per_hour"] = round(iph, 1)
        results["dataset_bench"] = {"images": count, "workers": 2, "wall_s": round(wall, 2), "gaussians": n_g,
                                    "bikes": desc, "rider": avatar_kind}
        from bench.provenance import record
        record(results, "dataset_images_per_hour", "fresh", bikes=desc, rider=avatar_kind)
        if chart:
            sweep = {"size": [], "gaussians": []}
            n = max(4, count // 4)
            for size in (128, 256, 512):
                iph_s, _, _ = measure(dict(base, count=n, image_size=size), 1, scratch, f"s{size}")
                sweep["size"].append((size, iph_s))
                print(f"dataset bench: 1 worker, {size}²: {iph_s:.0f} images/hour")
            if "SYNTHETIC" in desc:  # stand-in bikes: the Gaussian count is a free parameter
                for per_part in (1000, 5000, 20000):
                    cfg = dict(base, count=n, synthetic_gaussians_per_part=per_part)
                    ng = gaussian_count(resolve_assets(validate(cfg)))
                    iph_g, _, _ = measure(cfg, 1, scratch, f"g{per_part}")
                    sweep["gaussians"].append((ng, iph_g))
                    print(f"dataset bench: 1 worker, 512², {ng} Gaussians: {iph_g:.0f} images/hour")
            results["dataset_bench"]["sweep_1_worker"] = sweep
            _chart(sweep, os.path.join(out_dir, "dataset_throughput.png"), desc)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return results


def _chart(sweep, path, desc):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    panels = [k for k in ("size", "gaussians") if sweep[k]]
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 3.6), squeeze=False)
    for ax, k in zip(axes[0], panels):
        x, y = zip(*sweep[k])
        ax.plot(x, y, "o-")
        ax.set_xlabel("image size (px, square)" if k == "size" else "Gaussians per cyclist (512²)")
        ax.set_ylabel("images / hour (1 worker)")
        ax.axhline(30000, ls="--", c="gray", lw=0.8, label="60,000/h on 2 workers (goal)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"dataset throughput ({'synthetic' if 'SYNTHETIC' in desc else 'trained'} bikes)", fontsize=10)
    fig.tight_layout()
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None):
    ap = bench_parser("dataset", __doc__)
    ap.add_argument("--count", type=int, default=24)
    ap.add_argument("--no-chart", action="store_true")
    args = ap.parse_args(argv)
    results = {}
    run(results, args.out, args.count, not args.no_chart)
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

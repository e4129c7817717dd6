"""`make bench`: measure every stage on this machine -> out/bench/results.json + report.md + charts.

Each stage module exposes run(results, ...) and adds only the keys it measured in this run
(docs/contract.md's benchmark contract); a stage that fails is reported and its keys stay absent.
"""
import argparse
import importlib
import json
import os
import platform
import sys
import time
import traceback

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

# name -> (module, how to call run)
STAGES = {
    "raster": ("bench.raster", lambda m, r, out: m.run(r)),
    "bike_pose": ("bench.bike_pose", lambda m, r, out: m.run(r)),
    "render": ("bench.render", lambda m, r, out: m.run(r, out)),
    "views": ("bench.render", lambda m, r, out: m.render_all_views(out)),
    "train_parts": ("bench.train_parts", lambda m, r, out: m.run(r, os.path.join(out, "bikes"))),
    # the parts fine-tuned through the pose on posed renders (splatting/bike/posed_train.py), once
    "bike_posed_train": ("bench.train_parts", lambda m, r, out: m.run_posed(r, os.path.join(out, "bikes"))),
    "train_chart": ("bench.train_chart", lambda m, r, out: m.run(r, os.path.join(out, "bikes"),
                                                                 png=os.path.join(out, "train_chart.png"), time_budget_s=180)),
    "bike_gt": ("bench.bike_gt", lambda m, r, out: m.run(r, out)),
    "splat_import": ("bench.splat_import", lambda m, r, out: m.run(r, out)),
    "ik": ("bench.ik", lambda m, r, out: m.run(r, out)),
    "rider": ("bench.rider", lambda m, r, out: m.run(r, out)),
    "dataset": ("bench.dataset", lambda m, r, out: m.run(r, out)),
    "street": ("bench.street", lambda m, r, out: m.run(r, out)),
    "lod": ("bench.lod", lambda m, r, out: m.run(r, out, chart_png=os.path.join(out, "lod_chart.png"))),
    "bike_relit": ("bench.relight", lambda m, r, out: m.run_bench(r, out)),
    "rider_relit": ("bench.rider_relit", lambda m, r, out: m.run(r, out)),
    "library": ("bench.library", lambda m, r, out: m.run(r, out)),  # library_build_s, dataset_ray_overhead
    # gaussian_vs_blender_equal_fidelity: the trained bike vs Cycles/Workbench, interleaved (issue 14)
    "blender_compare": ("bench.blender_compare", lambda m, r, out: m.run(r, out)),
}

PAPER = {
    "render_view_s_median": "17–20 s per image",
    "bike_pose_ms_100k": "320 ms per pose",
    "ik_iter_ms": "860 ms per iteration",
    "rider_repose_ms": "1740 ms per frame",
}
TARGETS = {
    "render_view_s_median": "≤ 1.5 s",
    "render_psnr_vs_ref_db": "≥ 35 dB",
    "raster_fwdbwd_s": "≤ 0.06 s at 50k",
    "raster_fwd_ms": "≤ 15 ms at 50k",
    "raster_thread_scaling": "speedup ≥ 1.7",
    "train_parts": "≥ 30 dB in ≤ 600 s per part",
    "bike_pose_ms_100k": "≤ 5 ms",
    "bike_gt": "IoU ≥ 0.95, PSNR ≥ 28 dB (means)",
    "bike_fidelity": "box PSNR ≥ 32 dB, IoU ≥ 0.97 vs 512-spp Cycles at random poses (issue 14)",
    "splat_import": "camera mode within 2 dB of the rasterizer's box PSNR vs mesh, IoU ≥ 0.95 (gaussian mode: measured, order-bound)",
    "ik_iter_ms": "≤ 2 ms",
    "ik_batch_200x50_s": "≤ 2 s",
    "rider_gt": "IoU ≥ 0.9, PSNR ≥ 24 dB (means)",
    "dataset_images_per_hour": "≥ 60000 (issue 14)",
    "street_images_per_hour": "≥ 3000 (nuScenes 1600x900, 1-6 cyclists, photo backgrounds)",
    "lod_psnr_drop_db": "≤ 0.5 dB",
    "bike_relit": "box PSNR ≥ 30 dB, IoU ≥ 0.97 (means)",
    "rider_relit": "box PSNR ≥ 30 dB, IoU ≥ 0.97 (means)",
    "relight_render_overhead": "≤ 0.2",
    "dataset_ray_overhead": "< 0.1",
    "gaussian_vs_blender_equal_fidelity": "≥ 10",
}


def fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, dict):
        return ", ".join(f"{k}: {fmt(x)}" for k, x in v.items())
    if isinstance(v, list):
        return f"{len(v)} rows (see below)"
    return str(v)


def report(results, out_dir, timings):
    lines = ["# Benchmark report", "", f"Machine: {platform.machine()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}; measured {time.strftime('%Y-%m-%d %H:%M')}.", "",
             "| key | this run | target | paper |", "| --- | --- | --- | --- |"]
    for k, v in results.items():
        lines.append(f"| `{k}` | {fmt(v)} | {TARGETS.get(k, '')} | {PAPER.get(k, '')} |")
    if results.get("train_parts"):
        lines += ["", "## Per-part training (held-out views)", "", "| bike | part | PSNR | SSIM | Gaussians | wall s |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for r in results["train_parts"]:
            lines.append(f"| {r['bike']} | {r['part']} | {r['psnr']:.2f} | {r['ssim']:.4f} | {r['gaussians']} | {r['wall_s']:.0f} |")
    if results.get("blender_compare") and os.path.isfile(os.path.join(out_dir, "blender_compare_table.md")):
        with open(os.path.join(out_dir, "blender_compare_table.md")) as f:
            lines += ["", "## Gaussians vs Blender (blender_compare)", "", f.read().rstrip()]
    lines += ["", "## Stage wall times", ""] + [f"- {k}: {v:.0f} s" for k, v in timings.items()]
    charts = sorted(f for f in os.listdir(out_dir) if f.endswith(".png"))
    if charts:
        lines += ["", "## Charts", ""] + [f"![{c}]({c})" for c in charts]
    with open(os.path.join(out_dir, "report.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.run", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
    ap.add_argument("--stages", default=",".join(STAGES), help=f"comma list of {', '.join(STAGES)}")
    args = ap.parse_args(argv)
    stages = [s.strip() for s in args.stages.split(",") if s.strip()]
    unknown = [s for s in stages if s not in STAGES]
    if unknown:
        sys.stderr.write(f"bench: error: unknown stage '{unknown[0]}' (choose from {', '.join(STAGES)})\n")
        return 2
    os.makedirs(args.out, exist_ok=True)
    results, timings, failed = {}, {}, []
    for name in stages:
        mod_name, call = STAGES[name]
        print(f"== bench stage {name}", flush=True)
        t = time.time()
        try:
            call(importlib.import_module(mod_name), results, args.out)
        except Exception:
            traceback.print_exc()
            failed.append(name)
        timings[name] = time.time() - t
        tmp = os.path.join(args.out, ".results.json.tmp")
        with open(tmp, "w") as f:
            json.dump(results, f, indent=1)
        os.replace(tmp, os.path.join(args.out, "results.json"))
    report(results, args.out, timings)
    print(json.dumps(results, indent=1))
    if failed:
        sys.stderr.write(f"bench: stages failed: {', '.join(failed)}\n")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

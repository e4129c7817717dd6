"""`make bench`: measure every stage on this machine -> out/bench/results.json + report.md + charts.

Each stage module exposes run(results, ...) and adds only the keys it measured in this run
(docs/contract.md's benchmark contract); a stage that fails or skips is reported, its keys stay
absent and report.md says "not measured: <reason>".  Every key carries its provenance
(bench/provenance.py): fresh or reused, from which assets, with which fallback.
"""
import importlib
import json
import os
import platform
import sys
import time
import traceback

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench import bench_parser  # noqa: E402
from bench.provenance import META, not_measured, record  # noqa: E402

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
    "frames": ("bench.frames", lambda m, r, out: m.run(r, out)),  # cyclists inserted into KITTI frames (issue 26)
    "lidar": ("bench.lidar", lambda m, r, out: m.run(r, out)),  # road plane, LiDAR depth, scan insertion (issue 26)
    "sequence": ("bench.sequence", lambda m, r, out: m.run(r, out)),  # street sequences (issue 29)
    "motion_blur": ("bench.motion_blur", lambda m, r, out: m.run(r, out)),  # sub-frame blur vs a 33-sub-frame reference
    "lod": ("bench.lod", lambda m, r, out: m.run(r, out, chart_png=os.path.join(out, "lod_chart.png"))),
    "bike_relit": ("bench.relight", lambda m, r, out: m.run_bench(r, out)),
    "rider_relit": ("bench.rider_relit", lambda m, r, out: m.run(r, out)),
    # BlazePose on the roster riders at 64/128/256 px (mediapipe in its own venv: BLAZEPOSE_PYTHON; issue 28)
    "rider_realism": ("bench.rider_realism", lambda m, r, out: m.run(r, out)),
    "library": ("bench.library", lambda m, r, out: m.run(r, out)),  # library_build_s, dataset_ray_overhead
    # the real downloaded bikes: curated, built with the real-bike recipe, vs Blender (issue 27)
    "real_bikes": ("bench.real_bikes", lambda m, r, out: m.run(r, out)),
    # the development models' curation under real files' transformations (axes, units, mirror, joined; issue 27)
    "curation_stress": ("bench.curation_stress", lambda m, r, out: m.run(r, out)),
    # gaussian_vs_blender_equal_fidelity: the trained bike vs Cycles/Workbench, interleaved (issue 14)
    "blender_compare": ("bench.blender_compare", lambda m, r, out: m.run(r, out)),
}

# stages that add no results key by design: views renders the inputs of later stages, train_chart
# draws a chart (a skip still adds its "not measured" row)
NO_KEYS = {"views", "train_chart"}

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
    "raster_cameras": "speedup ≥ 1.3 (4 cameras in one call vs one call each, 50k, 512², 2 threads; issue 25)",
    "train_parts": "≥ 30 dB in ≤ 600 s per part",
    "bike_pose_ms_100k": "≤ 5 ms",
    "bike_gt": "IoU ≥ 0.95, PSNR ≥ 28 dB (means)",
    "bike_fidelity": "box PSNR ≥ 32 dB, IoU ≥ 0.97 vs 512-spp Cycles at random poses (issue 14)",
    "splat_import": "gaussian (any camera) and camera modes within 2 dB of the rasterizer's box PSNR vs mesh, IoU ≥ 0.95 (issue 31)",
    "ik_iter_ms": "≤ 2 ms",
    "ik_batch_200x50_s": "≤ 2 s",
    "rider_gt": "IoU ≥ 0.9, PSNR ≥ 24 dB (means)",
    "dataset_images_per_hour": "≥ 60000 (issue 14)",
    "street_images_per_hour": "≥ 3000 (nuScenes 1600x900, 1-6 cyclists, photo backgrounds)",
    "sequence_plausibility": "max_lateral_accel_mps2 ≤ bound (3.0), slip and cadence error ≈ 0",
    "frames_geometry": "tyres_within_3cm_share 1.0, labelled_box_overlaps 0",
    "lod_psnr_drop_db": "≤ 0.5 dB",
    "real_bikes": "≥ 5 development models at box PSNR ≥ 30 dB and IoU ≥ 0.97 (10 random poses each; issue 27)",
    "curation_stress": "usable share ≥ 0.8 (keypoints within 3 cm of the untransformed model's), 0 crashes (issue 27)",
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


def fmt_provenance(p):
    """'fresh' / 'reused (...)' plus the assets and fallbacks a key was measured with."""
    if not p:
        return "unrecorded"
    rest = "; ".join(f"{k}: {fmt(v)}" for k, v in p.items() if k != "status")
    return p.get("status", "unrecorded") + (f" ({rest})" if rest else "")


def report_lines(results, timings):
    """report.md's lines.  Values may be fresh or reused (the provenance column says which), so no
    column claims "this run"; a target key nobody measured, and every key a stage skipped or failed,
    is a "not measured: <reason>" row."""
    prov, skipped = results.get("provenance", {}), results.get("not_measured", {})
    lines = ["# Benchmark report", "", f"Machine: {platform.machine()}, {os.cpu_count()} cores, "
             f"Python {platform.python_version()}; written {time.strftime('%Y-%m-%d %H:%M')}.", "",
             "| key | value | provenance | target | paper |", "| --- | --- | --- | --- | --- |"]
    for k, v in results.items():
        if k not in META:
            lines.append(f"| `{k}` | {fmt(v)} | {fmt_provenance(prov.get(k))} | {TARGETS.get(k, '')} | {PAPER.get(k, '')} |")
    for k, why in skipped.items():
        if k not in results:
            lines.append(f"| `{k}` | not measured: {why} | | {TARGETS.get(k, '')} | {PAPER.get(k, '')} |")
    for k in TARGETS:
        if k not in results and k not in skipped and not any(x.startswith(k) for x in results):
            lines.append(f"| `{k}` | not measured: no stage of this run reported it | | {TARGETS[k]} | {PAPER.get(k, '')} |")
    if results.get("train_parts"):
        lines += ["", "## Per-part training (held-out views)", "", "| bike | part | PSNR | SSIM | Gaussians | wall s | provenance |",
                  "| --- | --- | --- | --- | --- | --- | --- |"]
        for r in results["train_parts"]:
            lines.append(f"| {r['bike']} | {r['part']} | {r['psnr']:.2f} | {r['ssim']:.4f} | {r['gaussians']} | {r['wall_s']:.0f} "
                         f"| {'reused' if r.get('reused') else 'fresh'} |")
    return lines


def report(results, out_dir, timings):
    lines = report_lines(results, timings)
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
    ap = bench_parser("run", __doc__)
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
        before = set(results)
        skipped_before = len(results.get("not_measured", {}))
        try:
            call(importlib.import_module(mod_name), results, args.out)
        except Exception as e:
            traceback.print_exc()
            failed.append(name)
            not_measured(results, f"stage {name}", f"failed: {type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}")
        added = [k for k in results if k not in before and k not in META]
        for k in added:  # a stage that read a value back records it as reused itself
            record(results, k, results.get("provenance", {}).get(k, {}).get("status", "fresh"), stage=name)
        if name not in failed and name not in NO_KEYS and not added and len(results.get("not_measured", {})) == skipped_before:
            not_measured(results, f"stage {name}", "the stage added no key (see its log)")
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

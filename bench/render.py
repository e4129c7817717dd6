"""Benchmark of the Blender view renderer: seconds per 512² RGBA+mask view and its noise.

`run(results, out_dir)` builds one procedural bike, then (in a separate Blender process, the
bpy module) renders a few ring views of the whole bike with several Cycles sample counts,
with and without the fast denoiser, and a 1024-sample non-adaptive reference of the same
views.  Noise is PSNR against that reference (RGB on black, 8-bit, whole image; the PSNR over
the object's pixels only is reported beside it).  Keys: render_view_s_median,
render_psnr_vs_ref_db (the default settings), plus a time-vs-PSNR chart.
"""
import argparse
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIGS = [(4, "NONE"), (8, "NONE"), (16, "NONE"), (32, "NONE"), (64, "NONE"),
           (4, "FAST"), (8, "FAST"), (16, "FAST"), (32, "FAST")]
PSNR_VIEWS = [3, 13, 27]  # three-quarter, near-rear and side-ish views
TIMING_VIEWS = list(range(0, 36, 4))  # 9 views for the median of the default settings
REF_SAMPLES = 1024


def psnr(a, b, mask=None):
    """PSNR of two 8-bit images (peak 255), over `mask` if given."""
    from splatting.training.metrics import psnr as _psnr

    return _psnr(a, b, mask, peak=255.0)


def worker(bike_dir, work_dir):
    """Runs inside a bpy process: all renders, timings and image comparisons."""
    sys.path.insert(0, ROOT)
    import bpy
    import numpy as np
    from PIL import Image

    from addon.core.render import render
    from addon.core.bike_asset import open_bike

    bike = open_bike(bike_dir)
    objs = list(bike["parts"].values())
    scene = bpy.context.scene
    render.setup_lighting(scene)
    kp = bike["keypoints"]

    def render_views(settings, views, tag):
        render.configure_cycles(scene, settings)
        out = os.path.join(work_dir, tag)
        times = []
        for v in views:
            t = time.perf_counter()
            render.render_part(scene, objs, out, kp, views=[v], settings=settings, progress=lambda *_: None)
            times.append(time.perf_counter() - t)
        return out, times

    def load(out, v):
        rgba = np.asarray(Image.open(os.path.join(out, "rgba", f"camera{v:04d}", "0000.png")).convert("RGBA"))
        a = rgba[..., 3:4].astype(np.float64) / 255
        return np.round(rgba[..., :3] * a), rgba[..., 3] > 127

    ref_settings = render.RenderSettings(samples=REF_SAMPLES, adaptive_threshold=0.0, denoise="NONE")
    ref_out, ref_times = render_views(ref_settings, PSNR_VIEWS, "ref")
    refs = {v: load(ref_out, v) for v in PSNR_VIEWS}

    rows = []
    for samples, denoise in CONFIGS:
        s = render.RenderSettings(samples=samples, denoise=denoise)
        out, times = render_views(s, [PSNR_VIEWS[0]] + PSNR_VIEWS, f"s{samples}_{denoise}")  # first = warm-up
        ps, pm, iou = [], [], []
        for v in PSNR_VIEWS:
            img, m = load(out, v)
            rimg, rm = refs[v]
            ps.append(psnr(img, rimg))
            pm.append(psnr(img, rimg, rm | m))
            iou.append(float((m & rm).sum() / max(1, (m | rm).sum())))
        rows.append({"samples": samples, "denoise": denoise, "s_median": float(np.median(times[1:])),
                     "psnr_db": float(np.mean(ps)), "psnr_object_db": float(np.mean(pm)),
                     "mask_iou_vs_ref": float(np.mean(iou))})
        print(f"  {samples:4d} spp denoise={denoise:5s} {rows[-1]['s_median']:.2f} s/view "
              f"PSNR {rows[-1]['psnr_db']:.1f} dB (object {rows[-1]['psnr_object_db']:.1f} dB) "
              f"mask IoU {rows[-1]['mask_iou_vs_ref']:.4f}", flush=True)

    default = render.RenderSettings()
    _, times = render_views(default, TIMING_VIEWS, "default")
    d_row = next((r for r in rows if r["samples"] == default.samples and r["denoise"] == default.denoise), None)
    return {"rows": rows, "ref_s_median": float(np.median(ref_times)),
            "default": {"samples": default.samples, "denoise": default.denoise,
                        "adaptive_threshold": default.adaptive_threshold, "max_bounces": default.max_bounces},
            "default_view_s": times, "default_psnr_db": d_row["psnr_db"] if d_row else None,
            "default_psnr_object_db": d_row["psnr_object_db"] if d_row else None,
            "default_mask_iou": d_row["mask_iou_vs_ref"] if d_row else None}


def chart(data, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for denoise, marker in (("NONE", "o"), ("FAST", "s")):
        rs = [r for r in data["rows"] if r["denoise"] == denoise]
        ax.plot([r["s_median"] for r in rs], [r["psnr_db"] for r in rs], marker=marker, label=f"denoise {denoise}")
        for r in rs:
            ax.annotate(f"{r['samples']}", (r["s_median"], r["psnr_db"]), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.axhline(35, color="grey", ls="--", lw=0.8)
    ax.axvline(1.5, color="grey", ls="--", lw=0.8)
    ax.set_xlabel("seconds per 512² view (Cycles CPU, 2 threads)")
    ax.set_ylabel(f"PSNR vs {REF_SAMPLES}-sample render (dB)")
    ax.set_title("Blender view rendering: speed vs noise (labels: samples)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def bench_bike(out_dir):
    """The benchmark's bike: road_00 of seed 0 (built once, reused by later stages)."""
    subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "make_bikes.py"), "--out", out_dir,
                    "--count", "1", "--seed", "0", "--no-extras"], check=True)
    bikes = os.path.join(out_dir, "bikes")
    return os.path.join(bikes, sorted(os.listdir(bikes))[0])


def render_all_views(out_dir):
    """All parts' 36 views of the benchmark bike with the default settings (resumable), for training."""
    bike_dir = bench_bike(out_dir)
    subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "render_views.py"), "--bike", bike_dir,
                    "--parts", "all"], check=True)


def run(results, out_dir):
    import statistics

    py = sys.executable
    bike_dir = bench_bike(out_dir)
    work = os.path.join(out_dir, "render_work")
    if os.path.isdir(work):
        import shutil

        shutil.rmtree(work)
    js = os.path.join(out_dir, "render_bench.json")
    subprocess.run([py, __file__, "--worker", bike_dir, work, js], check=True)
    with open(js) as f:
        data = json.load(f)
    results["render_view_s_median"] = statistics.median(data["default_view_s"])
    if data["default_psnr_db"] is not None:
        results["render_psnr_vs_ref_db"] = data["default_psnr_db"]
    else:
        from bench.provenance import not_measured
        not_measured(results, "render_psnr_vs_ref_db", "the default settings (samples, denoise) are not among the "
                     "sweep's rows compared with the reference")
    chart(data, os.path.join(out_dir, "render_speed_vs_noise.png"))
    return data


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="render benchmark worker (runs under bpy)")
    ap.add_argument("--worker", nargs=3, metavar=("BIKE_DIR", "WORK_DIR", "OUT_JSON"), required=True)
    a = ap.parse_args()
    data = worker(*a.worker[:2])
    with open(a.worker[2], "w") as f:
        json.dump(data, f, indent=1)

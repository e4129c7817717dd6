"""Level-of-detail benchmark (issue 12): the quality cost and the speed-up of fewer Gaussians.

What rendering a far cyclist with fewer Gaussians costs in image quality, and what it saves in
street-image time.

Quality, per level (share of Gaussians kept) and screen height: one cyclist (the street bench's
assets, a fixed pose, heading across the road) on the nuScenes camera (1600x900) at the distance
that makes it h px tall, rendered on black with the full model and with the level; a reference
rendered from the full model at 4x the resolution (with the same 0.3 px^2 low-pass in native
pixels: the same alpha field, sampled 16 times per pixel) and box-averaged down to the native
pixels (what an anti-aliased camera would see of the model).
- `psnr_vs_full_db`, `iou_vs_full`: the level against the full model at the same pose and
  camera (box PSNR over the union box of the two alpha > 0.5 masks; mask IoU);
- `drop_db` = box PSNR(full vs reference) - box PSNR(level vs reference): what the level costs
  relative to what the full model itself reaches at that size (< 0 = the level is closer).
Thresholds: a level is allowed below the largest measured height up to which its drop stays
<= 0.5 dB at every measured height; `chosen_levels` are those, `lod_psnr_drop_db` the largest drop
at the thresholds in force (splatting.cyclist.lod.DEFAULT_LEVELS unless --levels-from-table).
Speed: `lod_speedup` = the median over street images of CPU seconds with LOD off / with the
default LOD (the street bench's config: nuScenes, 1-6 cyclists, photo backgrounds, annotations;
make_sample, no file writing; the same images interleaved, one thread).  Chart: docs/img/lod_chart.png with --chart.
Run alone: `python -m bench.lod [--out DIR] [--images N] [--chart PNG]`.
"""
import json
import os
import statistics
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench import bench_parser  # noqa: E402

HEIGHTS_PX = (20, 30, 45, 55, 65, 90, 130, 180, 260, 380)
KEEPS = (0.7, 0.5, 0.35, 0.25)
DROP_DB = 0.5
SUPER = 4


def _box_psnr(a, b, m):
    ys, xs = np.nonzero(m)
    if not len(ys):
        return float("nan")
    sl = np.s_[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    mse = float(((a[sl] - b[sl]) ** 2).mean())
    return 10 * np.log10(1.0 / max(mse, 1e-12))


def _render(g, slots, cam):
    from splatting.cyclist.scene_render import render_scene
    L = render_scene(g, slots, 3, cam)
    return L["rgb"], L["alpha"]


def _reference(g, cam, box):
    """The model rendered at SUPER x the resolution with the same 0.3 px^2 low-pass in native pixels
    (the same alpha field, sampled SUPER^2 times per pixel) and box-averaged back to the native
    pixels of box (u0, v0, w, h): an anti-aliased camera's view of the model -> (h, w, 3)."""
    from splatting.cyclist.scene_render import cropped_camera
    from splatting.raster.api import render_gaussians
    u0, v0, w, h = box
    big = cropped_camera(cam.scaled(SUPER), (SUPER * u0, SUPER * v0, SUPER * w, SUPER * h))
    rgb = render_gaussians(g, big, eps2d=0.3 * SUPER * SUPER)["rgb"].numpy()
    return rgb.reshape(h, SUPER, w, SUPER, 3).mean((1, 3))


def quality_table(cfg, bike, rider, compensate=None, heights=HEIGHTS_PX, keeps=KEEPS, log=print):
    """Rows {height_px, keep, gaussians, psnr_vs_full_db, iou_vs_full, drop_db, full_vs_ref_db}."""
    import torch
    from cyclist_formats.instances import RIDER_ID
    from splatting.cyclist import lod
    from splatting.cyclist.scene_render import slot_boxes, union
    from splatting.dataset import camera_presets
    from splatting.dataset.generate import Assets, extent_box
    torch.set_num_threads(1)
    compensate = lod.DEFAULT_COMPENSATE if compensate is None else compensate
    assets = Assets(cfg)
    cyc = assets.cyclist(bike, rider)
    spec = camera_presets.resolve(cfg.camera.model_copy(update={"preset": "nuscenes", "scale": 1.0}))
    cam = camera_presets.street_camera(spec)
    base = [90.0, 5.0, 0.0, 180.0, 0.0, 0.0, 0.0, 10.0]  # side-on: crossing the road towards image-right
    f0 = cyc.pose(torch.tensor(base, dtype=torch.float64))[0]
    h_m = extent_box(f0.gaussians, base)["h"]
    order = lod.ranking(f0.gaussians, f0.ids)
    rows = []
    for hp in heights:
        pose = list(base)
        pose[7] = spec["fy"] * h_m / hp
        f = cyc.pose(torch.tensor(pose, dtype=torch.float64))[0]
        g, slots = f.gaussians, torch.where(f.ids == RIDER_ID, 2, 1).long()
        box = union(slot_boxes(g.means, g.scales, slots, 3, cam))
        sl = np.s_[box[1]:box[1] + box[3], box[0]:box[0] + box[2]]
        full, fa = (x[sl] for x in _render(g, slots, cam))
        ref = _reference(g, cam, box)
        fm = fa > 0.5
        p_full = _box_psnr(full, ref, fm)
        for k in keeps:
            sub, idx = lod.reduce(g, order, k, compensate, f.ids)
            img, a = (x[sl] for x in _render(sub, slots[idx], cam))
            m = a > 0.5
            row = {"height_px": hp, "keep": k, "gaussians": len(sub),
                   "psnr_vs_full_db": round(_box_psnr(img, full, m | fm), 2),
                   "iou_vs_full": round(float((m & fm).sum() / max(1, (m | fm).sum())), 4),
                   "full_vs_ref_db": round(p_full, 2),
                   "drop_db": round(p_full - _box_psnr(img, ref, fm), 3)}
            rows.append(row)
            log(f"lod: {hp:4d} px keep {k:5.2f}: vs full {row['psnr_vs_full_db']:6.2f} dB IoU {row['iou_vs_full']:.3f}"
                f" | drop vs reference {row['drop_db']:+.2f} dB (full {p_full:.2f} dB)")
    return rows


def choose_levels(rows, drop_db=DROP_DB):
    """Per keep: below_px = the largest height h with drop <= drop_db at every measured height <= h
    (levels whose smallest height already fails are left out); smaller keeps need smaller heights."""
    levels = []
    for k in sorted({r["keep"] for r in rows}, reverse=True):
        ok = 0
        for r in sorted((r for r in rows if r["keep"] == k), key=lambda r: r["height_px"]):
            if r["drop_db"] > drop_db:
                break
            ok = r["height_px"]
        if ok:
            levels.append({"below_px": ok, "keep": k})
    # a smaller level must not reach higher than a larger one; at the same height the smaller wins
    out, cap = [], float("inf")
    for lv in levels:
        cap = min(cap, lv["below_px"])
        if out and cap == out[-1]["below_px"]:
            out[-1] = {"below_px": cap, "keep": lv["keep"]}
        else:
            out.append({"below_px": cap, "keep": lv["keep"]})
    return out


def drop_at(rows, levels):
    """Largest drop over the measured heights with the level the thresholds give there."""
    from splatting.cyclist.lod import level_keep
    drops = [r["drop_db"] for r in rows if level_keep(r["height_px"], levels) == r["keep"]]
    return max(drops) if drops else 0.0  # < 0: the level is closer to the reference than the full model


def speed(cfg, n, log=print):
    """Median CPU seconds per street image with LOD off and on (the same images, interleaved) and the
    median of the per-image ratios off / on (paired: the images differ far more than LOD does)."""
    import torch
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets, make_sample
    torch.set_num_threads(1)
    on = resolve_assets(validate(dict(cfg, lod={"enabled": True})))
    off = resolve_assets(validate(dict(cfg, lod={"enabled": False})))
    a_on, a_off = Assets(on), Assets(off)
    make_sample(on, n, a_on)  # load assets outside the timing
    make_sample(off, n, a_off)
    t_on, t_off = [], []
    for i in range(n):
        for c, a, ts in ((off, a_off, t_off), (on, a_on, t_on)):
            t = time.process_time()  # CPU seconds (one thread): the shared machine's load stays out
            make_sample(c, i, a)
            ts.append(time.process_time() - t)
        log(f"lod: image {i}: off {t_off[-1]:.2f} s, on {t_on[-1]:.2f} s")
    return statistics.median(t_off), statistics.median(t_on), statistics.median(a / b for a, b in zip(t_off, t_on))


def chart(rows, levels, png, times=None):
    """Three panels over the screen height, one line per level: box PSNR and mask IoU against the
    full model, and the drop against the supersampled reference (0.5 dB line, thresholds in force)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, NullLocator
    from cyclist_formats.atomic import atomic_path
    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    heights = sorted({r["height_px"] for r in rows})
    for k in sorted({r["keep"] for r in rows}, reverse=True):
        rs = sorted((r for r in rows if r["keep"] == k), key=lambda r: r["height_px"])
        h = [r["height_px"] for r in rs]
        for a, key in zip(ax, ("psnr_vs_full_db", "drop_db", "iou_vs_full")):
            a.plot(h, [r[key] for r in rs], "o-", label=f"keep {k:g}")
    ax[1].axhline(DROP_DB, color="k", lw=0.8, ls="--")
    for lv in levels:
        ax[1].axvline(lv["below_px"], color="grey", lw=0.6, ls=":")
    ax[0].set(ylabel="box PSNR vs full model (dB)", title="level vs full model, same pose and camera")
    ax[1].set(ylabel="box PSNR drop (dB)", title="drop vs 4x supersampled full model (dotted: thresholds)")
    ax[2].set(ylabel="mask IoU vs full model", title="alpha > 0.5 mask vs full model")
    for a in ax:
        a.set_xscale("log")
        a.xaxis.set_minor_locator(NullLocator())
        a.xaxis.set_minor_formatter(NullFormatter())
        a.set_xticks(heights)
        a.set_xticklabels([str(h) for h in heights], fontsize=7)
        a.set_xlabel("cyclist height on screen (px)")
        a.legend(fontsize=7)
    if times:
        fig.suptitle(f"street image (nuScenes 1600x900, 1-6 cyclists): {times[0]:.2f} s without LOD, "
                     f"{times[1]:.2f} s with the default levels (median CPU s per image)", fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(png)), exist_ok=True)
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)


def run(results, out_dir, images=6, chart_png=None, log=print):
    from bench.street import RIDER, bench_config
    from splatting.cyclist.lod import DEFAULT_LEVELS
    from splatting.dataset.config import resolve_assets, validate
    scratch = tempfile.mkdtemp(prefix="bench_lod_")
    cfg, desc = bench_config(scratch, out_dir, images + 1)
    rcfg = resolve_assets(validate(cfg))
    log(f"lod bench: bikes: {desc}")
    rows = quality_table(rcfg, rcfg.bikes[0], RIDER, log=log)
    chosen = choose_levels(rows)
    drop = drop_at(rows, DEFAULT_LEVELS)
    t_off, t_on, ratio = speed(cfg, images, log=log)
    results["lod_speedup"] = round(ratio, 3)
    results["lod_psnr_drop_db"] = round(drop, 3)
    results["lod_bench"] = {"levels_in_force": DEFAULT_LEVELS, "chosen_levels": chosen, "s_per_image_off": round(t_off, 3),
                            "s_per_image_on": round(t_on, 3), "images": images, "bikes": desc, "table": rows}
    log(f"lod bench: median {t_off:.2f} s -> {t_on:.2f} s per street image, paired ratio x{ratio:.3f}; worst drop at the "
        f"levels in force {drop:.2f} dB; measured thresholds {chosen}")
    if chart_png:
        chart(rows, DEFAULT_LEVELS, chart_png, (t_off, t_on))
    return results


def main(argv=None):
    ap = bench_parser("lod", __doc__)
    ap.add_argument("--images", type=int, default=6, help="street images timed with LOD off and on")
    ap.add_argument("--chart", help="write the chart PNG here (e.g. docs/img/lod_chart.png)")
    args = ap.parse_args(argv)
    if args.images < 1:
        ap.error("--images must be >= 1")
    results = run({}, args.out, args.images, args.chart)
    print(json.dumps({k: v for k, v in results.items() if k != "lod_bench"}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

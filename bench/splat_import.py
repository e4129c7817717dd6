"""Gaussians imported into Blender (blender_scripts/import_splats.py) vs Blender's mesh render and
vs our rasterizer, at the same ring cameras (issue 17).

The bike: the first folder under OUT/bikes with views/whole (Blender's mesh render: rgba +
cameras.json) and trained Gaussians, either gaussians/whole.ply or the parts composed at the
rest pose (splatting.bike.BikeModel).  For each of 4 ring cameras (0, 9, 18, 27) it renders the
Gaussians with our rasterizer, and imports them into Blender once per mode (gaussian: ellipsoids
with falloff and SH; preview: spheres) and renders them with Cycles (16 samples, no denoising).

Metrics per image, RGB premultiplied on black in [0, 1]:
- box PSNR: PSNR over the bounding box of the union of both masks (alpha > 0.5), so empty
  background does not inflate it;
- IoU of the alpha > 0.5 masks;
- seconds per Cycles render (after import; the import is timed separately).
Key: splat_import = {cameras, gaussians, raster: {psnr_box_vs_mesh, iou_vs_mesh}, gaussian and
preview: {psnr_box_vs_mesh, iou_vs_mesh, psnr_box_vs_raster, iou_vs_raster, render_s_median,
import_s}}; side-by-side pictures beside results.json.
"""
import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAMERAS = (0, 9, 18, 27)
SAMPLES = int(os.environ.get("SPLAT_BENCH_SAMPLES", "16"))


def find_bike(bikes_dir):
    for b in sorted(os.listdir(bikes_dir)) if os.path.isdir(bikes_dir) else []:
        d = os.path.join(bikes_dir, b)
        g = os.path.join(d, "gaussians")
        if not os.path.isfile(os.path.join(d, "views", "whole", "cameras.json")):
            continue
        if os.path.isfile(os.path.join(g, "whole.ply")) or (
                os.path.isfile(os.path.join(g, "frame.ply")) and os.path.isfile(os.path.join(g, "steering.ply"))):
            return d
    return None


def gaussians_ply(bike_dir, work):
    """The bike's Gaussians as one .ply: gaussians/whole.ply, or the parts composed at rest."""
    whole = os.path.join(bike_dir, "gaussians", "whole.ply")
    if os.path.isfile(whole):
        return whole
    import torch

    from splatting.bike.model import BikeModel
    from splatting.gaussians.container import write_ply

    posed = BikeModel.load(bike_dir).pose(torch.zeros(8, dtype=torch.float64))
    path = os.path.join(work, "rest.ply")
    g = posed.gaussians
    write_ply(type(g)(means=g.means.contiguous(), quats=g.quats.contiguous(), log_scales=g.log_scales,
                      opacity_logits=g.opacity_logits, sh=g.sh.contiguous()), path)
    return path


def blender_worker(ply, cameras_json, cams, mode, out_dir):
    """Runs under bpy: import once, render each camera, time each render."""
    sys.path.insert(0, ROOT)
    import importlib.util

    from addon.core.scene import reset_scene
    from addon.core.splat_import import import_splats

    spec = importlib.util.spec_from_file_location("import_splats_script",
                                                  os.path.join(ROOT, "blender_scripts", "import_splats.py"))
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    scene = reset_scene()
    t0 = time.time()
    objs = import_splats([ply], mode=mode)
    timing = {"import_s": time.time() - t0, "render_s": []}
    for c in cams:
        args = argparse.Namespace(camera=f"{cameras_json}:camera{c:04d}", samples=SAMPLES, denoise="NONE",
                                  mode=mode, size=512, view=3)
        script.setup_render(scene, objs, args)
        from addon.core import render

        t = time.time()
        render.render_atomic(scene, os.path.join(out_dir, f"{mode}_{c:04d}.png"), derive=False)
        timing["render_s"].append(time.time() - t)
        print(f"  {mode}: camera {c} {timing['render_s'][-1]:.1f} s", flush=True)
    with open(os.path.join(out_dir, f"{mode}_timing.json"), "w") as f:
        json.dump(timing, f)


def _png(path):
    from PIL import Image

    im = np.asarray(Image.open(path).convert("RGBA")).astype(np.float64) / 255
    return im[..., :3] * im[..., 3:], im[..., 3] > 0.5


def run(results, out_dir, bike_dir=None, cams=CAMERAS, picture=None):
    bike_dir = bike_dir or find_bike(os.path.join(out_dir, "bikes"))
    if bike_dir is None:
        print("  splat_import: no bike with views/whole and trained Gaussians under", os.path.join(out_dir, "bikes"),
              "- skipped")
        return None
    import torch

    from bench.compare import mask_iou, side_by_side
    from splatting.training.metrics import box_psnr
    from splatting.raster.camera import load_cameras
    from splatting.gaussians.container import read_ply
    from splatting.raster.sparse import render_gaussians

    work = os.path.join(out_dir, "splat_import")
    os.makedirs(work, exist_ok=True)
    ply = gaussians_ply(bike_dir, work)
    cameras_json = os.path.join(bike_dir, "views", "whole", "cameras.json")
    for mode in ("gaussian", "preview"):
        subprocess.run([sys.executable, __file__, "--worker", ply, cameras_json, ",".join(map(str, cams)), mode, work],
                       check=True)
    g = read_ply(ply)
    ring, _ = load_cameras(cameras_json)
    rows = {"raster": [], "gaussian": [], "preview": []}
    pics = []
    with torch.no_grad():
        for c in cams:
            mesh, m_mesh = _png(os.path.join(bike_dir, "views", "whole", "rgba", f"camera{c:04d}", "0000.png"))
            out = render_gaussians(g, ring[c])
            ras, m_ras = out["rgb"].clamp(0, 1).numpy().astype(np.float64), out["alpha"].numpy() > 0.5
            rows["raster"].append({"psnr_box_vs_mesh": box_psnr(ras, mesh, m_ras, m_mesh),
                                   "iou_vs_mesh": mask_iou(m_ras, m_mesh)})
            for mode in ("gaussian", "preview"):
                bl, m_bl = _png(os.path.join(work, f"{mode}_{c:04d}.png"))
                rows[mode].append({"psnr_box_vs_mesh": box_psnr(bl, mesh, m_bl, m_mesh), "iou_vs_mesh": mask_iou(m_bl, m_mesh),
                                   "psnr_box_vs_raster": box_psnr(bl, ras, m_bl, m_ras), "iou_vs_raster": mask_iou(m_bl, m_ras)})
                if mode == "gaussian":
                    pics.append((ras, bl, mesh))
    summary = {"cameras": list(cams), "gaussians": len(g), "bike": os.path.basename(bike_dir.rstrip("/"))}
    for k, rs in rows.items():
        summary[k] = {m: float(np.mean([r[m] for r in rs])) for m in rs[0]}
    for mode in ("gaussian", "preview"):
        with open(os.path.join(work, f"{mode}_timing.json")) as f:
            t = json.load(f)
        summary[mode]["render_s_median"] = float(np.median(t["render_s"]))
        summary[mode]["import_s"] = float(t["import_s"])
    results["splat_import"] = summary
    ras, bl, mesh = pics[0]
    side_by_side(ras, bl, os.path.join(out_dir, "splat_import_cam0.png"))  # rasterizer | imported | 4x diff
    if picture:
        _picture(pics[0], summary, picture)
    print(json.dumps(summary, indent=1))
    return summary


def _picture(pic, s, path):
    """README picture: our rasterizer | the imported Gaussians in Cycles | Blender's mesh render, labelled."""
    from PIL import Image, ImageDraw

    ras, bl, mesh = pic
    ys, xs = np.nonzero((ras.max(-1) > 0.02) | (bl.max(-1) > 0.02) | (mesh.max(-1) > 0.02))
    pad = 12
    y0, y1 = max(ys.min() - pad, 0), min(ys.max() + pad + 1, ras.shape[0])
    x0, x1 = max(xs.min() - pad, 0), min(xs.max() + pad + 1, ras.shape[1])
    tiles = [np.clip(im[y0:y1, x0:x1], 0, 1) for im in (ras, bl, mesh)]
    strip = (np.concatenate(tiles, 1) * 255).round().astype(np.uint8)
    im = Image.fromarray(strip)
    canvas = Image.new("RGB", (im.width, im.height + 34), (0, 0, 0))
    canvas.paste(im, (0, 34))
    d = ImageDraw.Draw(canvas)
    w = tiles[0].shape[1]
    g, r = s["gaussian"], s["raster"]
    labels = [f"our rasterizer: {r['psnr_box_vs_mesh']:.1f} dB, IoU {r['iou_vs_mesh']:.3f}",
              f"Cycles import: {g['psnr_box_vs_mesh']:.1f} dB, IoU {g['iou_vs_mesh']:.3f}",
              "Blender mesh render (reference)"]
    for i, text in enumerate(labels):
        d.text((i * w + 6, 4), text, fill=(255, 255, 255))
    d.text((6, 18), f"box PSNR / mask IoU vs the mesh render, mean of ring cameras {','.join(map(str, s['cameras']))}",
           fill=(180, 180, 180))
    canvas.save(path)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="Gaussians imported into Blender vs mesh render vs rasterizer")
    ap.add_argument("--worker", nargs=5, metavar=("PLY", "CAMERAS_JSON", "CAMS", "MODE", "OUT_DIR"))
    ap.add_argument("--out", help="bench output folder (results + pictures)")
    ap.add_argument("--bike", help="bike folder (default: the first suitable one under OUT/bikes)")
    ap.add_argument("--picture", help="also write the labelled README picture here")
    a = ap.parse_args()
    if a.worker:
        blender_worker(a.worker[0], a.worker[1], [int(c) for c in a.worker[2].split(",")], a.worker[3], a.worker[4])
    else:
        sys.path.insert(0, ROOT)
        res = {}
        run(res, a.out, bike_dir=a.bike, picture=a.picture)

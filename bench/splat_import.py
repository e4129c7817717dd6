"""Gaussians imported into Blender (blender_scripts/import_splats.py) vs Blender's mesh render and
vs our rasterizer, at the same ring cameras (issues 17 and 31).

The bike: the first folder under OUT/bikes with views/whole (Blender's mesh render: rgba +
cameras.json) and trained Gaussians, either gaussians/whole.ply or the parts composed at the
rest pose (splatting.bike.BikeModel, drawn with the eps2d and mip filter the parts were trained
with).  For each of 4 ring cameras (0, 9, 18, 27) it renders the Gaussians with our rasterizer,
and imports them into Blender in each mode and renders them with Cycles, no denoising:
- gaussian: Gaussians on rectangles facing the camera, for any camera (imported once), 1 sample;
- camera: camera-facing quads that draw what the rasterizer draws (imported per camera), 1 sample;
- preview: spheres (imported once), SAMPLES samples;
- plate (only when asked for, --modes ...,plate): our rasterizer's own image (8-bit RGBA PNG) on a
  plane filling the camera's view, 1 sample: the faithful alternative for a fixed camera that
  is no import of the Gaussians at all.

Metrics per image, RGB premultiplied on black in [0, 1]:
- box PSNR: PSNR over the bounding box of the union of both masks (alpha > 0.5), so empty
  background does not inflate it;
- IoU of the alpha > 0.5 masks;
- seconds per Cycles render (after import; the import is timed separately).
Key: splat_import = {cameras, gaussians, samples, eps2d, antialiased, raster: {psnr_box_vs_mesh,
iou_vs_mesh}, gaussian, camera and preview: {psnr_box_vs_mesh, iou_vs_mesh, psnr_box_vs_raster,
iou_vs_raster, render_s_median, import_s}}; side-by-side pictures beside results.json.
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


def is_bike(d):
    """A bike folder with Blender's mesh render (views/whole) and trained Gaussians."""
    g = os.path.join(d, "gaussians")
    return os.path.isfile(os.path.join(d, "views", "whole", "cameras.json")) and (
        os.path.isfile(os.path.join(g, "whole.ply")) or
        (os.path.isfile(os.path.join(g, "frame.ply")) and os.path.isfile(os.path.join(g, "steering.ply"))))


def find_bike(bikes_dir):
    for b in sorted(os.listdir(bikes_dir)) if os.path.isdir(bikes_dir) else []:
        if is_bike(os.path.join(bikes_dir, b)):
            return os.path.join(bikes_dir, b)
    return None


def gaussians_ply(bike_dir, work):
    """The bike's Gaussians as one .ply, and the (eps2d, antialiased) they are drawn with:
    gaussians/whole.ply (the rasterizer's defaults), or the parts composed at rest (the model's)."""
    whole = os.path.join(bike_dir, "gaussians", "whole.ply")
    if os.path.isfile(whole):
        return whole, 0.3, False
    import torch

    from splatting.bike.model import BikeModel
    from splatting.gaussians.container import write_ply

    model = BikeModel.load(bike_dir)
    posed = model.pose(torch.zeros(8, dtype=torch.float64))
    path = os.path.join(work, "rest.ply")
    g = posed.gaussians
    write_ply(type(g)(means=g.means.contiguous(), quats=g.quats.contiguous(), log_scales=g.log_scales,
                      opacity_logits=g.opacity_logits, sh=g.sh.contiguous()), path)
    return path, float(model.eps2d), bool(model.antialiased)


MODES = ("gaussian", "camera", "preview")
ALL_MODES = MODES + ("plate",)
EXACT = ("gaussian", "camera", "plate")  # deterministic: the pixel-centre ray, no Russian roulette, 1 sample


def blender_worker(ply, cameras_json, cams, mode, out_dir, eps2d, antialiased):
    """Runs under bpy: import (once, or per camera in camera mode), render each camera, time each."""
    sys.path.insert(0, ROOT)
    import importlib.util

    from addon.core.render import render
    from addon.core.scene import reset_scene
    from addon.core.splats.splat_import import import_splats

    spec = importlib.util.spec_from_file_location("import_splats_script",
                                                  os.path.join(ROOT, "blender_scripts", "import_splats.py"))
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    timing = {"import_s": [], "render_s": []}
    scene = None
    for c in cams:
        args = argparse.Namespace(camera=f"{cameras_json}:camera{c:04d}", samples=1 if mode in EXACT else SAMPLES,
                                  denoise="NONE", mode="camera" if mode == "plate" else mode, size=512, view=3)
        camera = script.render_camera(args, [ply])
        if mode == "plate":
            scene = reset_scene()
            t0 = time.time()
            script.setup_render(scene, camera, args)  # the camera mode's settings: Raw, pixel-centre ray
            _plate(scene, os.path.join(out_dir, f"raster_{c:04d}.png"), camera)
            timing["import_s"].append(time.time() - t0)
        elif scene is None or mode == "camera":
            scene = reset_scene()
            t0 = time.time()
            import_splats([ply], mode=mode, camera=camera, eps2d=eps2d,
                          antialiased=antialiased and mode in EXACT)
            timing["import_s"].append(time.time() - t0)
        if mode != "plate":
            script.setup_render(scene, camera, args)
        t = time.time()
        render.render_atomic(scene, os.path.join(out_dir, f"{mode}_{c:04d}.png"), derive=False)
        timing["render_s"].append(time.time() - t)
        print(f"  {mode}: camera {c} {timing['render_s'][-1]:.1f} s", flush=True)
    with open(os.path.join(out_dir, f"{mode}_timing.json"), "w") as f:
        json.dump(timing, f)


def _plate(scene, png, camera):
    """A plane 1 m in front of the scene camera, exactly filling its view, emitting the straight
    RGBA PNG as is (Non-Color, nearest texel: pixel centres fall on texel centres)."""
    import bpy

    K, _, _, w, h = camera
    bpy.ops.mesh.primitive_plane_add(size=1.0)
    plane = bpy.context.active_object
    plane.scale = (w / K[0, 0], h / K[1, 1], 1.0)  # at 1 m the view is W / fx wide
    plane.parent, plane.location = scene.camera, (0.0, 0.0, -1.0)
    mat = bpy.data.materials.new("plate")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.load(png)
    tex.image.colorspace_settings.name = "Non-Color"
    tex.interpolation = "Closest"
    emit, clear, mix, out = (nt.nodes.new(t) for t in ("ShaderNodeEmission", "ShaderNodeBsdfTransparent",
                                                     "ShaderNodeMixShader", "ShaderNodeOutputMaterial"))
    nt.links.new(tex.outputs["Color"], emit.inputs["Color"])
    nt.links.new(tex.outputs["Alpha"], mix.inputs["Fac"])
    nt.links.new(clear.outputs[0], mix.inputs[1])
    nt.links.new(emit.outputs[0], mix.inputs[2])
    nt.links.new(mix.outputs[0], out.inputs["Surface"])
    plane.data.materials.append(mat)


def _png(path):
    from PIL import Image

    im = np.asarray(Image.open(path).convert("RGBA")).astype(np.float64) / 255
    return im[..., :3] * im[..., 3:], im[..., 3] > 0.5


def run(results, out_dir, bike_dir=None, cams=CAMERAS, picture=None, modes=MODES):
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
    from splatting.raster.api import render_gaussians

    work = os.path.join(out_dir, "splat_import")
    os.makedirs(work, exist_ok=True)
    ply, eps2d, antialiased = gaussians_ply(bike_dir, work)
    cameras_json = os.path.join(bike_dir, "views", "whole", "cameras.json")
    g = read_ply(ply)
    ring, _ = load_cameras(cameras_json)
    if "plate" in modes:  # the rasterizer's images, straight RGBA, for the plate's texture
        from PIL import Image

        with torch.no_grad():
            for c in cams:
                out = render_gaussians(g, ring[c], eps2d=eps2d, antialiased=antialiased)
                a = out["alpha"].numpy()[..., None]
                rgb = np.where(a > 0, out["rgb"].clamp(0, 1).numpy() / np.maximum(a, 1e-12), 0.0).clip(0, 1)
                Image.fromarray((np.concatenate([rgb, a], -1) * 255).round().astype(np.uint8), "RGBA").save(
                    os.path.join(work, f"raster_{c:04d}.png"))
    for mode in modes:
        subprocess.run([sys.executable, __file__, "--worker", ply, cameras_json, ",".join(map(str, cams)), mode, work,
                        str(eps2d), str(int(antialiased))], check=True)
    rows = {"raster": [], **{m: [] for m in modes}}
    pics = []
    with torch.no_grad():
        for c in cams:
            mesh, m_mesh = _png(os.path.join(bike_dir, "views", "whole", "rgba", f"camera{c:04d}", "0000.png"))
            out = render_gaussians(g, ring[c], eps2d=eps2d, antialiased=antialiased)
            ras, m_ras = out["rgb"].clamp(0, 1).numpy().astype(np.float64), out["alpha"].numpy() > 0.5
            rows["raster"].append({"psnr_box_vs_mesh": box_psnr(ras, mesh, m_ras, m_mesh),
                                   "iou_vs_mesh": mask_iou(m_ras, m_mesh)})
            ims = {}
            for mode in modes:
                bl, m_bl = _png(os.path.join(work, f"{mode}_{c:04d}.png"))
                rows[mode].append({"psnr_box_vs_mesh": box_psnr(bl, mesh, m_bl, m_mesh),
                                   "iou_vs_mesh": mask_iou(m_bl, m_mesh),
                                   "psnr_box_vs_raster": box_psnr(bl, ras, m_bl, m_ras),
                                   "iou_vs_raster": mask_iou(m_bl, m_ras)})
                ims[mode] = bl
            pics.append((ras, ims, mesh))
    summary = {"cameras": list(cams), "gaussians": len(g), "bike": os.path.basename(bike_dir.rstrip("/")),
               "samples": {m: 1 if m in EXACT else SAMPLES for m in modes}, "eps2d": eps2d,
               "antialiased": antialiased}
    for k, rs in rows.items():
        summary[k] = {m: float(np.mean([r[m] for r in rs])) for m in rs[0]}
        summary[k]["per_camera"] = rs
    for mode in modes:
        with open(os.path.join(work, f"{mode}_timing.json")) as f:
            t = json.load(f)
        summary[mode]["render_s_median"] = float(np.median(t["render_s"]))
        summary[mode]["render_s"] = t["render_s"]
        summary[mode]["import_s"] = float(np.median(t["import_s"]))
    results["splat_import"] = summary
    ras, ims, mesh = pics[0]
    for mode in modes:  # rasterizer | imported | 4x diff
        side_by_side(ras, ims[mode], os.path.join(out_dir, f"splat_import_cam0_{mode}.png"))
    if picture:
        _picture(pics[0], summary, picture)
    print(json.dumps(summary, indent=1))
    return summary


def _picture(pic, s, path):
    """README picture: our rasterizer | gaussian mode in Cycles | camera mode in Cycles | Blender's
    mesh render, labelled with the means over the cameras."""
    from PIL import Image, ImageDraw

    ras, ims, mesh = pic
    cols = [ras] + [ims[m] for m in ("gaussian", "camera") if m in ims] + [mesh]
    ys, xs = np.nonzero(np.any([im.max(-1) > 0.02 for im in cols], 0))
    pad = 12
    y0, y1 = max(ys.min() - pad, 0), min(ys.max() + pad + 1, ras.shape[0])
    x0, x1 = max(xs.min() - pad, 0), min(xs.max() + pad + 1, ras.shape[1])
    tiles = [np.clip(im[y0:y1, x0:x1], 0, 1) for im in cols]
    w = max(tiles[0].shape[1], 190)
    head = 48
    canvas = Image.new("RGB", (w * len(tiles), tiles[0].shape[0] + head), (0, 0, 0))
    d = ImageDraw.Draw(canvas)
    r = s["raster"]
    labels = [("our rasterizer", f"{r['psnr_box_vs_mesh']:.1f} dB, IoU {r['iou_vs_mesh']:.3f}")]
    for m, name in (("gaussian", "Cycles, any camera"), ("camera", "Cycles, camera mode")):
        if m in ims:
            g = s[m]
            labels.append((f"{name} ({s['samples'][m]} spp)", f"{g['psnr_box_vs_mesh']:.1f} dB, IoU {g['iou_vs_mesh']:.3f}; "
                                                                f"{g['psnr_box_vs_raster']:.1f} dB vs ours"))
    labels.append(("Blender mesh render", "(reference)"))
    for i, (tile, (a, b)) in enumerate(zip(tiles, labels)):
        canvas.paste(Image.fromarray((tile * 255).round().astype(np.uint8)), (i * w + (w - tile.shape[1]) // 2, head))
        d.text((i * w + 4, 4), a, fill=(255, 255, 255))
        d.text((i * w + 4, 17), b, fill=(255, 255, 255))
    d.text((4, 32), f"box PSNR / IoU vs the mesh render, mean of ring cameras {','.join(map(str, s['cameras']))}",
           fill=(170, 170, 170))
    canvas.save(path)


def main(argv=None):
    ap = argparse.ArgumentParser(description="Gaussians imported into Blender vs mesh render vs rasterizer")
    ap.add_argument("--worker", nargs=7, metavar=("PLY", "CAMERAS_JSON", "CAMS", "MODE", "OUT_DIR", "EPS2D", "AA"),
                    help=argparse.SUPPRESS)
    ap.add_argument("--out", help="bench output folder (results + pictures)")
    ap.add_argument("--bike", help="bike folder (default: the first suitable one under OUT/bikes)")
    ap.add_argument("--picture", help="also write the labelled README picture here")
    ap.add_argument("--modes", default=",".join(MODES), help=f"comma-separated subset of {','.join(ALL_MODES)}")
    a = ap.parse_args(argv)
    if a.worker:
        w = a.worker
        blender_worker(w[0], w[1], [int(c) for c in w[2].split(",")], w[3], w[4], float(w[5]), w[6] == "1")
        return 0
    modes = tuple(m for m in a.modes.split(",") if m)
    if not a.out:
        ap.error("--out is required")
    if not modes or any(m not in ALL_MODES for m in modes):
        ap.error(f"--modes must be a comma-separated subset of {','.join(ALL_MODES)}, got {a.modes}")
    if a.bike and not is_bike(a.bike):
        ap.error(f"--bike {a.bike} has no views/whole/cameras.json and trained Gaussians")
    sys.path.insert(0, ROOT)
    os.makedirs(a.out, exist_ok=True)
    res = {}
    run(res, a.out, bike_dir=a.bike, picture=a.picture, modes=modes)
    with open(os.path.join(a.out, "splat_import.json"), "w") as f:
        json.dump(res, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())

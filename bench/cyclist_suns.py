"""README picture: one whole cyclist (bike + rider) under four suns, Blender (top) beside the relit
Gaussians (bottom), with the box PSNR and mask IoU of each sun.

    python bench/cyclist_suns.py --bike BIKE_DIR --avatar AVATAR_DIR --out docs/img/cyclist_suns.png

Both need their relight channels (gaussians/PART.relight.npz, rider.relight.npz: relight-fit).
The Gaussian side is the dataset's: Cyclist poses the bike and fits the rider by IK, the normals
turn with the parts and the skinning (RelightableBike, RelightableAvatar), one rasterization
carries the relight channels with a per-Gaussian roughness (bike 0.4, rider 1.0), cast shadows
from the sun's shadow map.  Blender renders the bike's .blend posed by the same 8 values plus the
rider mesh posed by the same IK result (LBS), under the same sun and sky (bench/relight.py's
sun_and_sky).  The saddle auto-fit's slide is turned off on the Gaussian side: the .blend's saddle
does not slide.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
POSE = [70.0, 10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # theta_p, theta_s, H_g identity
CAMERA_AZIMUTH = 300.0
SAMPLES = 32  # the suns are bench/relit_suns.py's SUNS


def blender_worker(job_path):
    """Under bpy: the posed bike + the posed rider mesh, one render per sun."""
    sys.path.insert(0, ROOT)
    from dataclasses import replace

    import bpy

    from addon.core.render import render
    from addon.core.rig.articulation import apply_pose
    from addon.core.bike_asset import open_bike
    from addon.core.render.render_pose import load_camera
    from addon.core.rider.rider_import import import_rider
    from bench.relight import sun_and_sky

    with open(job_path) as f:
        job = json.load(f)
    s = replace(render.RenderSettings(), samples=job["samples"], threads=1)
    for i, light in enumerate(job["lights"]):
        out = os.path.join(job["out"], f"gt_{i}.png")
        if os.path.isfile(out):
            continue
        K, R, T = load_camera(job["camera"], job["bike"])
        bike = open_bike(job["bike"])
        scene = bpy.context.scene
        size = int(round(2 * K[0, 2]))
        render.configure_cycles(scene, replace(s, size=size))
        sun_and_sky(light)(scene)
        p = job["pose"]
        apply_pose(bike["armature"], p[0], p[1], tuple(p[2:5]), tuple(p[5:8]))
        rider = import_rider(job["mesh"], scene=scene)
        render.show_only(scene, list(bike["parts"].values()) + [rider])
        cam = render.ensure_camera(scene, size, K[0, 0])
        render.place_camera(cam, R, T)
        bpy.context.view_layer.update()
        render.render_atomic(scene, out)
        print(f"  blender sun {i + 1}/{len(job['lights'])}", flush=True)


def posed_cyclist(bike_dir, avatar_dir):
    """-> (posed Gaussians, reflectance, world normals, gloss, roughness, sky visibility (per Gaussian),
    rider body, IK rotations, root, the bike's world normal_view (its Gaussians come first) or None,
    how to draw them: {"antialiased", "eps2d"} for rasterize, each model as it was trained)."""
    import torch

    from cyclist_formats.instances import IDS
    from splatting.cyclist.compose import Cyclist, frame_eps2d
    from splatting.dataset.person_keypoints import RecordingAvatar
    from splatting.relight.avatar import RelightableAvatar, cyclist_static
    from splatting.relight.bike import RelightableBike
    from splatting.rider.roster import load_rider

    rb, ra = RelightableBike.load(bike_dir), RelightableAvatar.load(avatar_dir)
    rec = RecordingAvatar(ra.avatar)
    cyc = Cyclist(rb.model, rec)
    cyc.saddle_mask = None  # the .blend's saddle stays where it is
    pose = torch.tensor(POSE, dtype=torch.float64)
    frame, = cyc.pose(pose)
    rot, root = rec.last
    nrm = torch.cat([rb.posed_normals(pose), ra.posed_normals(rec.rotations[0])])
    alb, gl, rough, sky = cyclist_static(rb, ra)  # as relit datasets
    # as the datasets draw a cyclist: the bike's mip filter if its parts were trained with it, and
    # each model's own low-pass
    draw = {"antialiased": (frame.ids != IDS["rider"]) & bool(rb.model.antialiased),
            "eps2d": frame_eps2d(frame.ids, rb.model, ra.avatar)}
    return (frame.gaussians, alb + gl, nrm, gl, rough, sky, load_rider(ra.avatar.rider_id), rot, root,
            rb.posed_normal_view(pose), draw)


def render_relit_cyclist(g, refl, nrm, gl, rough, sky, camera, light, antialiased, eps2d):
    """One rasterization with the relight channels (reflectance as the colour), shaded per pixel;
    antialiased, eps2d: rasterize's (posed_cyclist's draw), the sun's shadow map's too."""
    from splatting.gaussians.container import Gaussians
    from splatting.gaussians.sh import C0
    from splatting.raster.api import render_gaussians
    from splatting.relight.render import relight_features, shade_composited
    from splatting.relight.shadow import sun_visibility

    feats = relight_features(nrm, gl, rough, sun_visibility(g, light, antialiased=antialiased, eps2d=eps2d), sky)
    gr = Gaussians(g.means, g.quats, g.log_scales, g.opacity_logits, ((refl.float() - 0.5) / C0)[:, None, :].contiguous())
    r = render_gaussians(gr, camera, features=feats, sh_degree=0, antialiased=antialiased, eps2d=eps2d)
    rgb = shade_composited(r["rgb"], r["features"], r["alpha"], camera, light, gloss=True, rough_channel=True,
                           shadows=True, sky_channel=True)
    return rgb.numpy().astype(np.float64), r["alpha"].numpy().astype(np.float64)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worker", metavar="JOB_JSON", help=argparse.SUPPRESS)
    ap.add_argument("--bike", help="trained bike folder with gaussians/PART.relight.npz and bike.blend")
    ap.add_argument("--avatar", help="trained avatar folder with rider.relight.npz")
    ap.add_argument("--out", help="PNG to write")
    ap.add_argument("--work", default=os.path.join(ROOT, "out", "cyclist_suns"))
    a = ap.parse_args()
    if a.worker:
        return blender_worker(a.worker)
    if not (a.bike and a.avatar and a.out):
        ap.error("--bike, --avatar and --out are required")
    if not os.path.isfile(os.path.join(a.avatar, "rider.relight.npz")):
        sys.exit(f"error: {a.avatar} has no rider.relight.npz (run relight-fit on it first)")
    if not os.path.isfile(os.path.join(a.bike, "bike.blend")):
        sys.exit(f"error: {a.bike} has no bike.blend (Blender renders the bike from it)")
    sys.path.insert(0, ROOT)
    import torch
    from PIL import Image

    from bench.compare import renders_for, score_png
    from bench.relight import light_json
    from bench.relit_suns import SUNS, four_suns, write_camera
    from splatting.raster.camera import ring_camera
    from splatting.rider.body import export_rider, pose_vertices

    torch.set_num_threads(1)
    g, refl, nrm, gl, rough, sky, rider, rot, root, nview, draw = posed_cyclist(a.bike, a.avatar)
    lo, hi = g.means.min(0).values.double(), g.means.max(0).values.double()
    cam = ring_camera(CAMERA_AZIMUTH, tuple(float(x) for x in (lo + hi) / 2), name="camera_suns")
    if nview is not None:  # a bike fitted with view-dependent normals: turned to this camera
        from splatting.relight.render import leading_view_normals
        nrm = leading_view_normals(nrm, nview, g.means, cam)
    os.makedirs(a.work, exist_ok=True)
    mesh = os.path.join(a.work, "rider_posed.ply")
    export_rider(rider, mesh, vertices=pose_vertices(rider, rot.double(), root.double())[0])
    cj = write_camera(cam, a.work)
    lights = four_suns()
    # Blender's renders in a.work are reused only for this bike (its files), rider, camera, suns and code
    from bench.provenance import RENDER_CODE, bike_assets, code_version
    renders_for(a.work, {**bike_assets(a.bike), "avatar": os.path.abspath(a.avatar), "pose": POSE,
                         "code": code_version(*RENDER_CODE, "splatting/rider"),
                         "camera": [cam.K.tolist(), cam.R.tolist(), cam.T.tolist()], "samples": SAMPLES,
                         "lights": [light_json(l) for l in lights]})
    jp = os.path.join(a.work, "job.json")
    with open(jp, "w") as f:
        json.dump({"bike": os.path.abspath(a.bike), "mesh": mesh, "camera": f"{cj}:{cam.name}", "pose": POSE,
                   "out": a.work, "samples": SAMPLES, "lights": [light_json(l) for l in lights]}, f)
    if subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", jp]).returncode:
        sys.exit("error: the Blender worker failed")
    top, bottom, rows = [], [], []
    for i, light in enumerate(lights):
        gt_png = os.path.join(a.work, f"gt_{i}.png")
        rgb, alpha = render_relit_cyclist(g, refl, nrm, gl, rough, sky, cam, light, **draw)
        iou, ps, gt_rgb, _ = score_png(gt_png, rgb, alpha)
        rows.append({"elevation_deg": SUNS[i][0], "azimuth_deg": SUNS[i][1], "box_psnr": round(ps, 2), "iou": round(iou, 4)})
        gt = np.asarray(Image.open(gt_png).convert("RGBA")).astype(np.float64) / 255
        top.append(gt[..., :3] * gt[..., 3:] + (1 - gt[..., 3:]))  # over white
        bottom.append(rgb + (1 - alpha[..., None]))
    m = np.nonzero(np.asarray(Image.open(os.path.join(a.work, "gt_0.png")).convert("RGBA"))[..., 3] > 0)
    y0, y1, x0, x1 = max(0, m[0].min() - 10), m[0].max() + 11, max(0, m[1].min() - 10), m[1].max() + 11
    grid = np.concatenate([np.concatenate([t[y0:y1, x0:x1] for t in row], 1) for row in (top, bottom)], 0)
    Image.fromarray((grid.clip(0, 1) * 255).round().astype(np.uint8)).save(a.out)
    with open(os.path.splitext(a.out)[0] + ".json", "w") as f:
        json.dump({"pose": POSE, "camera_azimuth_deg": CAMERA_AZIMUTH, "blender_samples": SAMPLES, "suns": rows}, f, indent=1)
    print(f"{a.out}: Blender (top) and the relit cyclist (bottom) under {len(SUNS)} suns")
    for r in rows:
        print(f"  sun {r['elevation_deg']:.0f}/{r['azimuth_deg']:.0f} deg: box PSNR {r['box_psnr']:.2f} dB, IoU {r['iou']:.4f}")


if __name__ == "__main__":
    main()

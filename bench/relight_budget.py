"""Where a relit render's error comes from, measured on Blender's own light passes (no Gaussians).

For bike_relit's random poses, cameras and suns, Blender renders the posed bike once with every
light pass (Diffuse/Glossy Color, Direct, Indirect, Emission, Normal) into a multilayer EXR. Cycles'
Combined is exactly DiffCol (DiffDir + DiffInd) + GlossCol (GlossDir + GlossInd) + Emit, so swapping
one measured term at a time for the shading model's prediction of it (splatting/relight/shading.py:
sun E cos/pi + uniform sky, from the pixel's own albedo, gloss and normal) says how many dB each
unmodelled effect costs: cast shadows and sky occlusion (diffuse direct), interreflection (diffuse
indirect), highlights and reflections (glossy), emission.  The ceiling row is the model fed with
perfect per-pixel passes: no Gaussian fit can beat it.  Cycles' AO pass prices the sky's occlusion
by the object (model_sky_times_blender_ao: both sky terms scaled by it); --split renders each pose
a second time under its sun alone, so the gloss splits into the sun's highlight and the sky's
reflection (Cycles counts the world as a light: both land in Glossy Direct).

    python bench/relight_budget.py --bike OUT/bikes/ID --out DIR [--size 256 --poses 6 --split]
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Blender 3.4's pass names and 5.0's
PASS_NAMES = {"AO": "Ambient Occlusion"}
LIGHT_PASSES = {"DiffDir": "Diffuse Direct", "DiffInd": "Diffuse Indirect", "DiffCol": "Diffuse Color",
                "GlossDir": "Glossy Direct", "GlossInd": "Glossy Indirect", "GlossCol": "Glossy Color",
                "Emit": "Emission", "Normal": "Normal"}


def worker(job_path):
    """Under bpy: each pose rendered once with every light pass, saved as a multilayer EXR."""
    sys.path.insert(0, ROOT)
    from dataclasses import replace

    import bpy

    from addon.core.render import passes, render
    from addon.core.render.render_pose import render_pose

    from bench.relight import sun_and_sky

    with open(job_path) as f:
        job = json.load(f)
    s = replace(render.RenderSettings(), samples=job["samples"], threads=1, denoise="NONE")
    runs = [(i, "", light) for i, light in enumerate(job["lights"])]
    if job.get("split"):  # the same pose under its sun alone (sky black): the sky's share is the difference
        runs += [(i, "_sun", dict(light, sky=[0.0, 0.0, 0.0])) for i, light in enumerate(job["lights"])]
    for i, tag, light in runs:
        pose, cam = job["poses"][i], job["cameras"][i]
        exr = os.path.join(job["out"], f"passes_{i:03d}{tag}.exr")
        if os.path.isfile(exr):
            continue
        lighting = sun_and_sky(light)

        def setup(scene, lighting=lighting):  # after render_pose opened the bike (its own view layer)
            lighting(scene)
            vl = bpy.context.view_layer
            for attr in ("diffuse_direct", "diffuse_indirect", "diffuse_color", "glossy_direct", "glossy_indirect",
                         "glossy_color", "emit", "normal", "ambient_occlusion"):
                setattr(vl, f"use_pass_{attr}", True)
        render.setup_lighting = setup
        render_pose(job["bike"], pose, cam, os.path.join(job["out"], f"rgba_{i:03d}{tag}.png"), None, s,
                    lights_follow=False)
        passes.save_exr(bpy.context.scene, exr + ".tmp")
        os.replace(exr + ".tmp", exr)
        print(f"  budget pose {i + 1}/{len(job['poses'])}{tag}", flush=True)


def _pass(ch, name, comps="RGB"):
    names = (name, LIGHT_PASSES.get(name, PASS_NAMES.get(name, name)))
    for key in ch:
        lp, _, c = key.rpartition(".")
        if lp.rpartition(".")[2] in names and c == comps[0]:
            base = key[:-len(c)]
            return np.stack([ch[base + x] for x in comps], -1).astype(np.float64)
    raise KeyError(name)


def display(lin, alpha):
    """Premultiplied linear -> premultiplied sRGB display (as shading.shade)."""
    a = alpha[..., None]
    straight = np.where(a > 1e-6, lin / np.maximum(a, 1e-6), 0.0).clip(0, 1)
    s = np.where(straight <= 0.0031308, 12.92 * straight, 1.055 * straight ** (1 / 2.4) - 0.055)
    return s * a


def analyse(exr_path, light, camera, grid=(), sun_exr=None, gauss_vis=None):
    """One pose's EXR -> {row: box PSNR (dB) against Blender's Combined}.  `grid`: extra
    (roughness, highlight) pairs to try for the gloss (how ROUGHNESS/HIGHLIGHT were chosen).
    sun_exr: the same pose under its sun alone (--split): the gloss then splits into what the sun
    and what the sky put there (Cycles counts the world as a light, so both are Glossy Direct).
    gauss_vis: (sun visibility, sky visibility) (H, W) straight, composited from the bike's
    Gaussians in this pose and view (--gaussians): the ceiling with the model's own cast shadows
    and sky occlusion."""
    import torch

    from addon.core import frames
    from addon.core.render import passes

    from bench.compare import psnr
    from splatting.raster.camera import from_numpy
    from splatting.relight.shading import Light, shade_linear, view_directions

    ch = passes.read_exr(exr_path)
    P = {k: _pass(ch, k, "XYZ" if k == "Normal" else "RGB") for k in LIGHT_PASSES}
    ao = _pass(ch, "AO", "RGB").mean(-1)  # Cycles' ambient occlusion, premultiplied like the rest
    comb4 = _pass(ch, "Combined", "RGBA")
    alpha, comb = comb4[..., 3], comb4[..., :3]
    n = frames.to_canonical(P["Normal"].reshape(-1, 3)).reshape(P["Normal"].shape)
    L = Light(**light)
    cam = from_numpy(camera["K"], camera["R"], camera["T"], dtype=torch.float64)
    view = view_directions(cam, torch.float64)
    t = lambda x: torch.from_numpy(np.ascontiguousarray(x))  # noqa: E731
    zero = torch.zeros(alpha.shape + (3,), dtype=torch.float64)
    diff_model = shade_linear(t(P["DiffCol"]), t(n), L).numpy()
    gloss_model = lambda **kw: shade_linear(zero, t(n), L, t(P["GlossCol"]), **kw).numpy()  # noqa: E731
    truth = {"diff_dir": P["DiffCol"] * P["DiffDir"], "diff_ind": P["DiffCol"] * P["DiffInd"],
             "gloss": P["GlossCol"] * (P["GlossDir"] + P["GlossInd"]), "emit": P["Emit"]}
    model = {"diff_dir": diff_model, "diff_ind": 0 * comb, "gloss": gloss_model(view=view), "emit": 0 * comb}
    m = alpha > 0.5
    ys, xs = np.nonzero(m)
    H, W = alpha.shape
    y0, y1, x0, x1 = max(0, ys.min() - 8), min(H, ys.max() + 9), max(0, xs.min() - 8), min(W, xs.max() + 9)
    score = lambda img: psnr(display(img, alpha)[y0:y1, x0:x1], display(comb, alpha)[y0:y1, x0:x1])  # noqa: E731
    rest = truth["diff_dir"] + truth["diff_ind"] + truth["emit"]
    out = {"recompose_check": score(sum(truth.values())), "model": score(sum(model.values())),
           "model_gloss_diffuse_like": score(sum(model.values()) - model["gloss"] + gloss_model(view=None)),
           "model_gloss_sky_only": score(sum(model.values()) - model["gloss"] + gloss_model(view=view, highlight=0.0))}
    for k in truth:  # only term k modelled, the rest exact: the dB that term costs
        out[f"only_{k}_modelled"] = score(sum(model[j] if j == k else truth[j] for j in truth))
    # the sky occluded by the object (what the model leaves out): both sky terms scaled by Blender's AO
    occl = np.where(alpha > 1e-3, ao / np.maximum(alpha, 1e-3), 1.0).clip(0, 1)[..., None]
    sky_d = P["DiffCol"] * np.asarray(L.sky)  # the passes are premultiplied already
    sky_g = P["GlossCol"] * np.asarray(L.sky)
    out["model_sky_times_blender_ao"] = score(sum(model.values()) - (1 - occl) * (sky_d + sky_g))
    if sun_exr:
        chs = passes.read_exr(sun_exr)
        g_sun = _pass(chs, "GlossCol") * (_pass(chs, "GlossDir") + _pass(chs, "GlossInd"))
        g_sky = truth["gloss"] - g_sun
        sun_model = model["gloss"] - sky_g
        rest = truth["diff_dir"] + truth["diff_ind"] + truth["emit"]
        out["only_gloss_sky_modelled"] = score(rest + g_sun + sky_g)
        out["only_gloss_sun_modelled"] = score(rest + g_sky + sun_model)
        out["only_gloss_sun_dropped"] = score(rest + g_sky)
        tot_g = float(truth["gloss"][y0:y1, x0:x1].sum())
        out["sun_share_of_gloss"] = round(float(g_sun[y0:y1, x0:x1].sum()) / max(tot_g, 1e-12), 3)
    if gauss_vis is not None:
        V, S = (t(x[..., None]) for x in gauss_vis)
        with_vis = lambda **kw: (shade_linear(t(P["DiffCol"]), t(n), L, **kw)  # noqa: E731
                                 + shade_linear(zero, t(n), L, t(P["GlossCol"]), view=view, **kw)).numpy()
        out["model_gauss_shadows"] = score(with_vis(sun_visibility=V))
        out["model_gauss_shadows_sky"] = score(with_vis(sun_visibility=V, sky_visibility=S))
    for r, h in grid:
        out[f"gloss_r{r}_h{h}"] = score(rest + gloss_model(view=view, roughness=r, highlight=h))
    tot = sum(float(v[y0:y1, x0:x1].sum()) for v in truth.values())
    out["share"] = {k: round(float(v[y0:y1, x0:x1].sum()) / tot, 3) for k, v in truth.items()}
    return out


def gaussian_visibility(bike, poses, cams_json, lights):
    """Per pose: the bike's Gaussians' sun visibility (cast shadows) and sky visibility (its
    RelightableBike.sky_visibility), composited in that pose and view, straight (H, W) numpy."""
    import torch

    from splatting.raster.camera import from_numpy
    from splatting.raster.api import render_gaussians
    from splatting.relight.bike import RelightableBike
    from splatting.relight.shading import Light
    from splatting.relight.shadow import sun_visibility

    rb = RelightableBike.load(bike)
    sky = rb.sky_visibility()
    out = []
    with torch.no_grad():
        for pose, cam, light in zip(poses, cams_json, lights):
            g = rb.model.pose(torch.as_tensor(pose, dtype=torch.float64)).gaussians.map(lambda x: x.contiguous())
            f = torch.stack([sun_visibility(g, Light(**light)), sky], 1).contiguous()
            r = render_gaussians(g, from_numpy(cam["K"], cam["R"], cam["T"]), features=f, sh_degree=0)
            a = r["alpha"].numpy()[..., None].astype(np.float64)
            # where the Gaussians do not cover Blender's pixel they say nothing: unoccluded
            st = np.where(a > 0.02, r["features"].numpy() / np.maximum(a, 0.02), 1.0).clip(0, 1)
            out.append((st[..., 0], st[..., 1]))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worker", metavar="JOB_JSON", help=argparse.SUPPRESS)
    ap.add_argument("--bike", help="a bike folder (bike.blend)")
    ap.add_argument("--out", help="output folder")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--poses", type=int, default=6)
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--seed", type=int, default=0, help="poses sample_poses(n, seed), suns seeded seed + 16 (as bike_relit)")
    ap.add_argument("--grid", action="store_true", help="also try a grid of gloss roughness x highlight")
    ap.add_argument("--gaussians", action="store_true", help="also price the model with the bike's Gaussians' own "
                    "sun visibility and sky visibility (its trained gaussians/ and relight fits)")
    ap.add_argument("--split", action="store_true", help="also render each pose under its sun alone (sky black) to "
                    "split the gloss into its sun and sky parts")
    a = ap.parse_args()
    if a.worker:
        return worker(a.worker)
    if not a.bike or not a.out:
        ap.error("--bike and --out are required")
    if not os.path.isfile(os.path.join(a.bike, "bike.blend")):
        sys.exit(f"error: no bike.blend in {a.bike}")
    if a.gaussians and not os.path.isfile(os.path.join(a.bike, "gaussians", "frame.relight.npz")):
        sys.exit(f"error: --gaussians: no relight fits in {a.bike}/gaussians (run relight-fit first)")
    sys.path.insert(0, ROOT)
    import torch

    from bench.bike_gt import sample_poses
    from bench.relight import light_json, ring_camera_files
    from splatting.relight.shading import random_light

    from bench.compare import renders_for
    from bench.provenance import RENDER_CODE, bike_assets, code_version, file_hash

    poses, cams = sample_poses(a.poses, a.seed)
    rng = np.random.default_rng(a.seed + 16)
    lights = [light_json(random_light(rng)) for _ in range(a.poses)]
    # earlier passes in --out are reused only when made for this bike, poses, suns, size, samples and code
    renders_for(a.out, {**bike_assets(a.bike), "poses": poses.tolist(), "cameras": cams.tolist(), "size": a.size,
                        "frame_cameras": file_hash(os.path.join(a.bike, "views", "frame", "cameras.json")),
                        "samples": a.samples, "lights": lights, "code": code_version(*RENDER_CODE)},
                prefix=("passes_", "rgba_"))
    job = {"bike": os.path.abspath(a.bike), "poses": poses.tolist(), "out": os.path.abspath(a.out), "samples": a.samples,
           "cameras": ring_camera_files(a.bike, cams, a.size, a.out), "lights": lights, "split": a.split}
    jp = os.path.join(a.out, "budget_job.json")
    with open(jp, "w") as f:
        json.dump(job, f)
    r = subprocess.run([sys.executable, __file__, "--worker", jp], cwd=ROOT)
    if r.returncode:
        sys.exit("error: the Blender worker failed")
    del torch
    grid = [(r, h) for r in (0.2, 0.3, 0.4) for h in (0.25, 0.5, 1.0)] if a.grid else ()
    cams_json = []
    for p in job["cameras"]:
        with open(p) as f:
            cams_json.append(json.load(f))
    vis = gaussian_visibility(a.bike, poses, cams_json, lights) if a.gaussians else [None] * a.poses
    rows = [analyse(os.path.join(a.out, f"passes_{i:03d}.exr"), lights[i], cams_json[i], grid,
                    os.path.join(a.out, f"passes_{i:03d}_sun.exr") if a.split else None, vis[i]) for i in range(a.poses)]
    keys = [k for k in rows[0] if k != "share"]
    summary = {k: round(float(np.mean([r[k] for r in rows])), 2) for k in keys}
    summary["share"] = {k: round(float(np.mean([r["share"][k] for r in rows])), 3) for k in rows[0]["share"]}
    print(json.dumps({"per_pose": rows, "mean": summary}, indent=1))
    with open(os.path.join(a.out, "budget.json"), "w") as f:
        json.dump({"per_pose": rows, "mean": summary}, f, indent=1)


if __name__ == "__main__":
    main()

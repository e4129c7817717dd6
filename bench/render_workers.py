"""Persistent render workers for bench/blender_compare.py: one process per engine that loads its
scene or model once and then renders pose after pose on request.

    python -m bench.render_workers --engine blender|gauss --bike OUT/bikes/ID

Protocol: one JSON object per line on stdin, one JSON reply per line on the worker's original
stdout (Blender's own log lines are sent to stderr, so they cannot corrupt the replies).
    {"op": "render", "pose": [8 floats], "K": 3x3, "R": 3x3, "T": 3, "threads": n,
     "method": {...}, "out": "FILE.png"}  ->  {"ok": true, "s": seconds}
    {"op": "quit"}
`s` is the time from posing to the finished image in memory (Blender: the render call; Gaussians:
posing + rasterising + conversion to 8-bit); writing the PNG afterwards is not timed on either side.
Methods: {"engine": "cycles", "samples", "denoise" ("NONE"/"FAST"), "adaptive" (threshold, 0 = off),
"seed"}, {"engine": "workbench"}, {"engine": "gauss", "antialiased": bool}.
An error is answered with {"ok": false, "error": "..."}; the worker keeps serving.
"""
import argparse
import json
import os
import sys
import time
import traceback

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


class BlenderScene:
    """The bike's .blend opened once; lights that follow the bike's global pose (as bike_gt)."""

    def __init__(self, bike_dir):
        import bpy

        from addon.core.render import render
        from addon.core.bike_asset import open_bike

        self.bpy, self.render = bpy, render
        self.bike = open_bike(bike_dir)
        self.scene = bpy.context.scene
        render.configure_cycles(self.scene, render.RenderSettings())
        render.setup_lighting(self.scene)
        render.show_only(self.scene, list(self.bike["parts"].values()))
        self.lights = {o.name: o.matrix_world.copy() for o in self.scene.objects if o.type == "LIGHT"}
        self.cam = None

    def configure(self, method, threads, size):
        from dataclasses import replace

        r, sc = self.render, self.scene
        if method["engine"] == "cycles":
            s = replace(r.RenderSettings(), samples=int(method["samples"]), denoise=method.get("denoise", "NONE"),
                        adaptive_threshold=float(method.get("adaptive", 0.05)), seed=int(method.get("seed", 0)),
                        threads=threads, size=size)
            r.configure_cycles(sc, s)
        elif method["engine"] == "workbench":
            sc.render.engine = "BLENDER_WORKBENCH"
            sc.render.resolution_x = sc.render.resolution_y = size
            sc.render.resolution_percentage = 100
            sc.render.film_transparent = True
            sc.render.threads_mode = "FIXED"
            sc.render.threads = threads
            sh = sc.display.shading
            sh.light = "STUDIO"
            sh.color_type = "MATERIAL"  # the materials' base colours, the closest Workbench gets
            sc.display.render_aa = "8"
        else:
            raise ValueError(f"blender worker: unknown engine {method['engine']!r}")

    def render_image(self, pose, K, R, T, out):
        import mathutils

        from addon.core import frames
        from addon.core.rig.articulation import apply_pose, global_matrix

        bpy, r, sc = self.bpy, self.render, self.scene
        size = sc.render.resolution_x
        t0 = time.perf_counter()
        apply_pose(self.bike["armature"], pose[0], pose[1], tuple(pose[2:5]), tuple(pose[5:8]))
        # the Gaussians carry the shading they were trained with; the suns move with the bike (bike_gt)
        Hb = mathutils.Matrix(frames.matrix_to_blender(global_matrix(pose[2:5], pose[5:8])).tolist())
        for o in sc.objects:
            if o.type == "LIGHT":
                o.matrix_world = Hb @ self.lights[o.name]
        self.cam = r.ensure_camera(sc, size, float(K[0][0]))
        r.place_camera(self.cam, R, T)
        bpy.context.view_layer.update()
        bpy.ops.render.render(write_still=False)
        s = time.perf_counter() - t0
        from cyclist_formats.atomic import atomic_path

        with atomic_path(out) as tmp:
            bpy.data.images["Render Result"].save_render(filepath=tmp)
        return s


class GaussianScene:
    """The trained part Gaussians (BikeModel) loaded once."""

    def __init__(self, bike_dir):
        import torch

        from splatting.bike.model import BikeModel

        self.torch = torch
        self.model = BikeModel.load(bike_dir)

    def configure(self, method, threads, size):
        if method["engine"] != "gauss":
            raise ValueError(f"gauss worker: unknown engine {method['engine']!r}")
        self.torch.set_num_threads(threads)
        self.antialiased = bool(method.get("antialiased", False))

    def render_image(self, pose, K, R, T, out):
        import numpy as np
        from PIL import Image

        from splatting.raster.camera import from_numpy
        from splatting.raster.api import render_gaussians

        torch = self.torch
        cam = from_numpy(K, R, T)
        with torch.no_grad():
            t0 = time.perf_counter()
            posed = self.model.pose(torch.tensor(pose, dtype=torch.float64))
            o = render_gaussians(posed.gaussians, cam, antialiased=self.antialiased,
                                 eps2d=self.model.eps2d)  # the low-pass the parts were trained with
            rgba = torch.cat([o["rgb"], o["alpha"][..., None]], -1)
            # straight alpha like Blender's PNG: colour / alpha where something was hit
            rgba[..., :3] /= o["alpha"].clamp_min(1e-6)[..., None]
            img = (rgba.clamp(0, 1) * 255).round().to(torch.uint8).numpy()
            s = time.perf_counter() - t0
        from cyclist_formats.atomic import atomic_path

        with atomic_path(out) as tmp:
            Image.fromarray(np.ascontiguousarray(img), "RGBA").save(tmp, format="PNG")
        return s


def serve(engine, bike_dir):
    proto = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # Blender and OpenMP print to fd 1: keep the protocol channel clean
    sys.stdout = sys.stderr
    sys.path.insert(0, ROOT)
    scene = BlenderScene(bike_dir) if engine == "blender" else GaussianScene(bike_dir)
    proto.write(json.dumps({"ok": True, "ready": engine}) + "\n")
    for line in sys.stdin:
        cmd = json.loads(line)
        if cmd.get("op") == "quit":
            break
        try:
            size = int(round(2 * float(cmd["K"][0][2])))
            scene.configure(cmd["method"], int(cmd["threads"]), size)
            s = scene.render_image(cmd["pose"], cmd["K"], cmd["R"], cmd["T"], cmd["out"])
            reply = {"ok": True, "s": s}
        except Exception as e:  # reported to the caller, which fails the stage with this message
            traceback.print_exc()
            reply = {"ok": False, "error": f"{type(e).__name__}: {e}"}
        proto.write(json.dumps(reply) + "\n")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(prog="python -m bench.render_workers", description=__doc__.splitlines()[0])
    ap.add_argument("--engine", choices=("blender", "gauss"), required=True)
    ap.add_argument("--bike", required=True, help="bike folder (bike.blend; gaussians/ for --engine gauss)")
    a = ap.parse_args()
    if not os.path.isdir(a.bike):
        sys.stderr.write(f"render_workers: error: no bike folder: {a.bike}\n")
        raise SystemExit(2)
    serve(a.engine, a.bike)

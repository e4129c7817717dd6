"""Build a rider's Gaussian avatar (the command: `python -m splatting rider-avatar --id ID`, rider/command.py).

Steps, each skipped when its output exists (so a killed run resumes):
  0. look.json       the look the rider is trained in (avatar_look.py), written first: datasets read it to
                     know what the avatar wears.  A folder that already holds a build keeps its record; one
                     whose record names another rider or look is refused (its steps would be skipped and
                     the avatar be of the other look), one built before the record existed gets none
  1. rest_mesh.ply   the T-posed rider mesh with vertex colours (body.export_rider); with bare, the rider
                     redressed in the accessory-free look (looks.BARE): the base datasets add per-instance
                     accessories to (splatting/cyclist/accessories.py; default folder <avatar>/bare/)
  2. views/          36 ring views in Blender (blender_scripts/render_rider.py, a subprocess)
  3. rider.ply       Gaussians trained on those views (splatting.training.trainer; rider.json = metrics)
  4. skinning.npz    per-Gaussian LBS weights from the body model (avatar.RiderAvatar)
"""
import json
import os
import subprocess
import sys
import time

import torch

from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import updated
from splatting import paths
from splatting.gaussians.container import read_ply
from splatting.rider.avatar import PLY_NAME, RiderAvatar, SKINNING_NAME
from splatting.rider.avatar_look import LOOK_NAME, look_record, read_look, write_look
from splatting.rider.body import export_rider, redress
from splatting.rider.looks import BARE
from splatting.rider.roster import load_rider
from splatting.training.trainer import train, TrainConfig

RENDER_SCRIPT = paths.blender_script("render_rider.py")
N_VIEWS = 36


def views_complete(views_dir, n=N_VIEWS):
    return all(os.path.isfile(os.path.join(views_dir, "rgba", f"camera{i:04d}", "0000.png")) for i in range(n))


def render_views(mesh, views_dir, samples=None, python=None, log=print, size=None):
    """Run the Blender side (bpy module in this venv by default) on the rest mesh."""
    cmd = [python or sys.executable, RENDER_SCRIPT, "--mesh", mesh, "--out", views_dir]
    if samples:
        cmd += ["--samples", str(samples)]
    if size:
        cmd += ["--size", str(size)]
    log(f"rider-avatar: rendering 36 views ({' '.join(cmd[1:])})")
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0 or not views_complete(views_dir):
        tail = "\n".join(r.stdout.strip().splitlines()[-5:])
        raise UserError(f"Blender rendering of {mesh} failed (exit {r.returncode}): {tail}")


def build_avatar(rider_id, out_dir, iterations=None, time_budget_s=None, max_gaussians=None, samples=None,
                 threads=1, log=print, size=None, bare=False):
    """Run the four steps; returns {"avatar": out_dir, "steps": {step: seconds or "skipped"}, "train": metrics}."""


    rider = load_rider(rider_id)  # UserError for an unknown id, before any work
    if bare:
        rider = redress(rider, **BARE)  # UserError for a body without a roster look
    mesh = os.path.join(out_dir, "rest_mesh.ply")
    views = os.path.join(out_dir, "views")
    ply = os.path.join(out_dir, PLY_NAME)
    skin = os.path.join(out_dir, SKINNING_NAME)
    started = any(os.path.exists(p) for p in (mesh, views, ply, skin))
    record = read_look(out_dir) if os.path.isdir(out_dir) else None  # UserError for a corrupt one
    if started and record is not None and record != look_record(rider):
        raise UserError(f"{out_dir} holds an avatar build of rider {record['rider']} in another look ({LOOK_NAME}: "
                        f"{record['look']}); move it away or choose another --out")
    os.makedirs(out_dir, exist_ok=True)
    steps = {}
    if not started:
        write_look(out_dir, rider)
    elif record is None:  # what it was trained in is unknown: no record rather than a guess
        log(f"rider-avatar: {out_dir} was built before avatars recorded their look; no {LOOK_NAME} written "
            f"(datasets drawing accessories per instance refuse it: move it away and rebuild for them)")

    def step(name, done, fn):
        if done:
            steps[name] = "skipped"
            return
        t = time.time()
        fn()
        steps[name] = round(time.time() - t, 2)
        log(f"rider-avatar: {name} done in {steps[name]} s")

    step("mesh", os.path.isfile(mesh), lambda: export_rider(rider, mesh))
    # an imported rider's own file carries its textures: the training views draw them (docs/rider_import.md)
    views_mesh = rider.spec["rider_file"] if rider.spec.get("body") == "imported" else mesh
    step("views", views_complete(views), lambda: render_views(views_mesh, views, samples, log=log, size=size))

    def do_train():
        cfg = TrainConfig(threads=threads)
        given = {k: v for k, v in (("iterations", iterations), ("time_budget_s", time_budget_s)) if v}
        cfg = updated(cfg, **given, **({"densify": {"max_gaussians": max_gaussians}} if max_gaussians else {}))
        m = train(views, ply, cfg)
        log(f"rider-avatar: {m['gaussians']} Gaussians, held-out PSNR {m['psnr']} dB (over white)")

    step("train", os.path.isfile(ply), do_train)

    def do_skin():
        torch.set_num_threads(threads)
        RiderAvatar.from_rider(read_ply(ply), rider).save_skinning(out_dir)

    step("skinning", os.path.isfile(skin), do_skin)
    metrics_path = os.path.join(out_dir, "rider.json")
    metrics = json.load(open(metrics_path)) if os.path.isfile(metrics_path) else None
    return {"avatar": out_dir, "steps": steps, "train": metrics}

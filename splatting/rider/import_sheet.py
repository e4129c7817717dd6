"""Imported riders on a bike: the IK's residuals and posed textured meshes for a contact sheet.

    python -m splatting rider import-sheet --bike out/demo/bikes/city_00 --rider NAME=rider.npz ... \
        --work DIR [--out docs/img/riders_import.png] [--table FILE.md]

For each rider file: the IK (saddle fitted, one seat post) at four crank angles on the bike's keypoints,
the worst residual of the hands (wrists -> handles), feet (ankles -> pedals) and pelvis (-> seat) over
them, and the rider posed at crank angle 0 written as a rider file (the same faces, UVs and textures),
which blender_scripts/render_rider_on_bike.py draws on the bike at its rest pose (crank angle 0) into
one picture per rider; the pictures are tiled into the contact sheet with a label each.
"""
import json
import math
import os
import subprocess
import sys

import numpy as np
import torch

from cyclist_formats import rider_file
from cyclist_formats.errors import UserError
from splatting import paths

CRANK_DEG = (0.0, 90.0, 180.0, 270.0)
SCRIPT = paths.blender_script("render_rider_on_bike.py")


def ride(npz, keypoints):
    """(residuals {hands, feet, pelvis} metres (worst over CRANK_DEG), posed vertices at crank 0 (V,3))."""
    from splatting.rider import ik
    from splatting.rider.body import pose_vertices
    from splatting.rider.imported import load_imported_rider
    from splatting.rotations import rodrigues
    rider = load_imported_rider(npz)
    poses = torch.tensor([[p, 0, 0, 0, 0, 0, 0, 0] for p in CRANK_DEG], dtype=torch.float64)
    targets = ik.posed_bike_keypoints(keypoints, poses)
    res = ik.solve(rider.joints.double(), targets, saddle_fit=True, saddle_shared=True)
    worst = {}
    for part, pairs in (("hands", ("left_wrist->handle_left", "right_wrist->handle_right")),
                        ("feet", ("left_ankle->pedal_left", "right_ankle->pedal_right")),
                        ("pelvis", ("pelvis->seat",))):
        worst[part] = max(float(res.residuals[p].max()) for p in pairs)
    rot = rodrigues(res.local_aa[:1].reshape(-1, 3)).reshape(1, 24, 3, 3)
    verts = pose_vertices(rider, rot, res.root_trans[:1])[0].numpy()
    return worst, verts


def import_sheet(bike, riders, work, out=None, table=None, size=360, samples=16):
    """riders: [(name, rider.npz)]; the residuals printed one rider a line, the table (markdown) written
    to `table`, the pictures rendered into `work` and tiled into `out` (each optional)."""
    kp_path = os.path.join(bike, "keypoints.json")
    if not os.path.isfile(kp_path):
        raise UserError(f"--bike {bike}: no keypoints.json")
    keypoints = json.load(open(kp_path))["keypoints"]
    os.makedirs(work, exist_ok=True)
    rows, jobs = [], []
    for name, path in riders:
        worst, verts = ride(path, keypoints)
        a, meta = rider_file.read_rider_file(path)
        extra = {k: a[k] for k in ("uv", "face_texture") if k in a}
        if "uv" in a:
            extra["textures"] = rider_file.textures_of(a)
        posed = os.path.join(work, f"{name}_posed.npz")
        W = np.zeros_like(a["weights"])
        W[:, 0] = 1.0  # a posed snapshot: not for skinning
        rider_file.write_rider_file(posed, meta=dict(meta, posed="crank 0 on " + os.path.basename(bike)),
                                    vertices=verts, faces=a["faces"], joints=a["joints"], weights=W,
                                    colors=a["colors"], **extra)
        png = os.path.join(work, f"{name}.png")
        jobs.append({"rider": posed, "out": png, "label": name})
        rows.append((name, meta, worst))
        print(f"{name}: hands {worst['hands'] * 100:.2f} cm, feet {worst['feet'] * 100:.2f} cm, "
              f"pelvis {worst['pelvis'] * 100:.2f} cm", flush=True)
    if table:
        lines = ["| rider | rig (scheme) | rest pose | size | placed joints | missing textures | hands / feet / pelvis (cm, worst of 4 crank angles) |",
                 "| --- | --- | --- | --- | --- | --- | --- |"]
        for name, meta, w in rows:
            placed = ", ".join(meta.get("placed_joints") or {}) or "none"
            lines.append(f"| {name} | {meta['scheme']} | {meta['rest_pose']} | {meta.get('size', '')} | {placed} | "
                         f"{len(meta.get('missing_textures') or [])} | {w['hands'] * 100:.2f} / {w['feet'] * 100:.2f} / "
                         f"{w['pelvis'] * 100:.2f} |")
        open(table, "w").write("\n".join(lines) + "\n")
    if out:
        job_file = os.path.join(work, "jobs.json")
        json.dump(jobs, open(job_file, "w"))
        r = subprocess.run([sys.executable, SCRIPT, "--bike", bike, "--jobs", job_file, "--size", str(size),
                            "--samples", str(samples)])
        if r.returncode != 0:
            raise UserError("render_rider_on_bike.py failed")
        from PIL import Image, ImageDraw
        tiles = [Image.open(j["out"]).convert("RGB") for j in jobs]
        cols = 3
        rows_n = math.ceil(len(tiles) / cols)
        sheet = Image.new("RGB", (cols * size, rows_n * size), "white")
        for k, (t, j) in enumerate(zip(tiles, jobs)):
            x, y = (k % cols) * size, (k // cols) * size
            sheet.paste(t, (x, y))
            ImageDraw.Draw(sheet).text((x + 6, y + 6), j["label"], fill=(0, 0, 0))
        os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
        sheet.save(out)
        print(f"wrote {out}")
    return 0


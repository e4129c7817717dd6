"""Imported riders on a bike: the IK's residuals and posed textured meshes for a contact sheet.

    python -m bench.rider_import_sheet --bike out/demo/bikes/city_00 --rider NAME=rider.npz ... \
        [--avatar NAME=AVATAR_FOLDER ...] --work DIR [--out docs/img/riders_import.png] [--table FILE.md]

For each rider file: the IK (saddle fitted, one seat post) at four crank angles on the bike's keypoints,
the worst residual of the hands (wrists -> handles), feet (ankles -> pedals) and pelvis (-> seat) over
them, and the rider posed at crank angle 0 written as a rider file (the same faces, UVs and textures),
which blender_scripts/render_rider_on_bike.py draws on the bike at its rest pose (crank angle 0) into
one picture per rider; the pictures are tiled into the contact sheet with a label each.  With --avatar,
a rider's trained Gaussian avatar (`rider-avatar`) rides the bike's trained Gaussians (splatting.cyclist,
the same IK, crank angle 0) and is drawn by the rasterizer from the same camera: one more tile each.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np
import torch

from cyclist_formats import rider_file
from cyclist_formats.errors import UserError
from splatting import paths
from bench import labelled_sheet, main_with_errors, save_png

CRANK_DEG = (0.0, 90.0, 180.0, 270.0)
SCRIPT = paths.blender_script("render_rider_on_bike.py")


def ride(npz, keypoints):
    """(residuals {hands, feet, pelvis} metres (worst over CRANK_DEG), posed vertices at crank 0 (V,3))."""
    from splatting.bike.pose import posed_bike_keypoints
    from splatting.rider import ik
    from splatting.rider.body import pose_vertices
    from splatting.rider.imported import load_imported_rider
    from splatting.rotations import rodrigues
    rider = load_imported_rider(npz)
    poses = torch.tensor([[p, 0, 0, 0, 0, 0, 0, 0] for p in CRANK_DEG], dtype=torch.float64)
    targets = posed_bike_keypoints(keypoints, poses)
    res = ik.solve(rider.joints.double(), targets, saddle_fit=True, saddle_shared=True)
    worst = {}
    for part, pairs in (("hands", ("left_wrist->handle_left", "right_wrist->handle_right")),
                        ("feet", ("left_ankle->pedal_left", "right_ankle->pedal_right")),
                        ("pelvis", ("pelvis->seat",))):
        worst[part] = max(float(res.residuals[p].max()) for p in pairs)
    rot = rodrigues(res.local_aa[:1].reshape(-1, 3)).reshape(1, 24, 3, 3)
    verts = pose_vertices(rider, rot, res.root_trans[:1])[0].numpy()
    return worst, verts


def look_at(eye, at, size, focal):
    """A pinhole camera (x right, y down, z ahead) at eye looking at at, world up +Y (canonical frame)."""
    from splatting.raster.camera import from_numpy
    eye, at = np.asarray(eye, float), np.asarray(at, float)
    z = (at - eye) / np.linalg.norm(at - eye)
    x = np.cross(np.array([0.0, -1.0, 0.0]), z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    K = np.array([[focal, 0, size / 2], [0, focal, size / 2], [0, 0, 1.0]])
    return from_numpy(K, R, -R @ eye, size, size)


def avatar_tile(bike_dir, folder, out, size):
    """The trained avatar in `folder` on the bike's trained Gaussians at crank angle 0, rasterized from the
    Blender tiles' camera (render_rider_on_bike.py) over the same grey; returns the IK residuals."""
    from PIL import Image
    from splatting.bike.model import BikeModel
    from splatting.cyclist.compose import Cyclist
    from splatting.cyclist.render import over, render_layers
    from splatting.rider.avatar import RiderAvatar
    sys.path.insert(0, os.path.dirname(SCRIPT))
    from render_rider_on_bike import CAMERA_CANONICAL, TARGET_CANONICAL  # the Blender tiles' camera
    frame = Cyclist(BikeModel.load(bike_dir), RiderAvatar.load(folder)).pose(
        torch.zeros(1, 8, dtype=torch.float64), saddle_shared=True)[0]
    cam = look_at(CAMERA_CANONICAL, TARGET_CANONICAL, size, 0.9 * size)
    layers = render_layers(frame.gaussians, frame.ids, cam)
    grey = np.array([184, 186, 189]) / 255.0  # the Blender tiles' world colour as it comes out of Cycles
    Image.fromarray(over(layers, np.broadcast_to(grey, (size, size, 3)))).save(out)
    return frame.ik["residual_m"]


def render_on_bike(jobs, work, bike, size, samples):
    """Blender renders of the posed riders of `jobs` ({"rider": rider file, "out": png, ...}) sitting on
    `bike` (blender_scripts/render_rider_on_bike.py, one process for all)."""
    job_file = os.path.join(work, "jobs.json")
    with open(job_file, "w") as f:
        json.dump(jobs, f)
    r = subprocess.run([sys.executable, SCRIPT, "--bike", bike, "--jobs", job_file, "--size", str(size),
                        "--samples", str(samples)])
    if r.returncode != 0:
        raise UserError("render_rider_on_bike.py failed")

def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.rider_import_sheet", description=__doc__.splitlines()[0])
    p.add_argument("--bike", required=True, help="a bike folder with keypoints.json and bike.blend")
    p.add_argument("--rider", action="append", required=True, help="NAME=rider.npz (repeatable)")
    p.add_argument("--avatar", action="append", default=[],
                   help="NAME=a trained avatar folder (rider.ply, skinning.npz) to draw on the bike's Gaussians (repeatable)")
    p.add_argument("--work", required=True, help="folder for the posed rider files and the pictures")
    p.add_argument("--out", help="the contact sheet .png")
    p.add_argument("--table", help="write the residual table (markdown) here")
    p.add_argument("--size", type=int, default=360, help="pixels per picture (default 360)")
    p.add_argument("--samples", type=int, default=16, help="Cycles samples per picture (default 16)")
    args = p.parse_args(argv)
    kp_path = os.path.join(args.bike, "keypoints.json")
    if not os.path.isfile(kp_path):
        raise UserError(f"--bike {args.bike}: no keypoints.json")
    keypoints = json.load(open(kp_path))["keypoints"]
    riders = []
    for r in args.rider:
        name, _, path = r.partition("=")
        if not path or not os.path.isfile(path):
            raise UserError(f"--rider {r}: give NAME=an existing rider.npz")
        riders.append((name, path))
    avatars = []
    for r in args.avatar:
        name, _, folder = r.partition("=")
        if not folder or not os.path.isfile(os.path.join(folder, "skinning.npz")):
            raise UserError(f"--avatar {r}: give NAME=a trained avatar folder (with skinning.npz)")
        avatars.append((name, folder))
    os.makedirs(args.work, exist_ok=True)
    rows, jobs = [], []
    for name, path in riders:
        worst, verts = ride(path, keypoints)
        a, meta = rider_file.read_rider_file(path)
        extra = {k: a[k] for k in ("uv", "face_texture") if k in a}
        if "uv" in a:
            extra["textures"] = rider_file.textures_of(a)
        posed = os.path.join(args.work, f"{name}_posed.npz")
        W = np.zeros_like(a["weights"])
        W[:, 0] = 1.0  # a posed snapshot: not for skinning
        rider_file.write_rider_file(posed, meta=dict(meta, posed="crank 0 on " + os.path.basename(args.bike)),
                                    vertices=verts, faces=a["faces"], joints=a["joints"], weights=W,
                                    colors=a["colors"], **extra)
        png = os.path.join(args.work, f"{name}.png")
        jobs.append({"rider": posed, "out": png, "label": name})
        rows.append((name, meta, worst))
        print(f"{name}: hands {worst['hands'] * 100:.2f} cm, feet {worst['feet'] * 100:.2f} cm, "
              f"pelvis {worst['pelvis'] * 100:.2f} cm", flush=True)
    if args.table:
        lines = ["| rider | rig (scheme) | rest pose | size | placed joints | missing textures | hands / feet / pelvis (cm, worst of 4 crank angles) |",
                 "| --- | --- | --- | --- | --- | --- | --- |"]
        for name, meta, w in rows:
            placed = ", ".join(meta.get("placed_joints") or {}) or "none"
            lines.append(f"| {name} | {meta['scheme']} | {meta['rest_pose']} | {meta.get('size', '')} | {placed} | "
                         f"{len(meta.get('missing_textures') or [])} | {w['hands'] * 100:.2f} / {w['feet'] * 100:.2f} / "
                         f"{w['pelvis'] * 100:.2f} |")
        open(args.table, "w").write("\n".join(lines) + "\n")
    if args.out:
        render_on_bike(jobs, args.work, args.bike, args.size, args.samples)
        from PIL import Image
        for name, folder in avatars:
            png = os.path.join(args.work, f"{name}_avatar.png")
            res = avatar_tile(args.bike, folder, png, args.size)
            print(f"{name} (avatar): worst IK residual {max(res.values()) * 100:.2f} cm", flush=True)
            jobs.append({"out": png, "label": f"{name} (trained Gaussians)"})
        tiles = [Image.open(j["out"]).convert("RGB") for j in jobs]
        save_png(labelled_sheet(tiles, [j["label"] for j in jobs], 3, (184, 186, 189)), args.out)
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    main_with_errors(main, "import_sheet")

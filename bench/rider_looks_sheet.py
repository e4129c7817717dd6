"""The roster riders in their looks, posed on a bike by the IK and drawn by Blender: a contact sheet.

    python -m bench.rider_looks_sheet --bike out/demo/bikes/city_00 --work DIR --out docs/img/rider_looks_roster.png \
        [--riders ID,ID,...] [--size 300 --samples 16 --cols 5]

Each anny roster rider (splatting.rider.roster, dressed by splatting/rider/looks.py) goes through the IK
(saddle fitted, one seat post) to the bike's keypoints at crank angle 0; its mesh posed by the rider's own
skinning is written as a rider file (vertex colours, the helmet, hair and backpack included), which
blender_scripts/render_rider_on_bike.py draws on the bike's bike.blend at its rest pose, seen from the
rider's left; the pictures are tiled with each rider's id and look.  Pictures that exist are kept (resumable).
"""
import argparse
import json
import os
import sys

import numpy as np
import torch

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from cyclist_formats import rider_file  # noqa: E402
from cyclist_formats.errors import UserError  # noqa: E402
from bench import labelled_sheet, main_with_errors, save_png  # noqa: E402
from bench.rider_import_sheet import render_on_bike  # noqa: E402



def posed_on_bike(rider, keypoints):
    """(V, 3) the rider's vertices posed by the IK on the bike at crank angle 0, and the worst residual (m)."""
    from splatting.bike.pose import posed_bike_keypoints
    from splatting.rider import ik
    from splatting.rider.body import pose_vertices
    from splatting.rotations import rodrigues
    targets = posed_bike_keypoints(keypoints, torch.zeros(1, 8, dtype=torch.float64))
    res = ik.solve(rider.joints.double(), targets, saddle_fit=True, saddle_shared=True)
    rot = rodrigues(res.local_aa[:1].reshape(-1, 3)).reshape(1, 24, 3, 3)
    worst = max(float(v.max()) for v in res.residuals.values())
    return pose_vertices(rider, rot, res.root_trans[:1])[0].numpy(), worst


def label(spec):
    """The tile's caption lines: the id, then its look."""
    from splatting.rider.looks import look_of
    lk = look_of(spec)
    extras = ", ".join(x for x, on in (("helmet", lk["helmet"]), ("backpack", lk["bag"] == "backpack")) if on) or "no helmet"
    return [spec["id"], f"{lk['top_pattern']} top, {lk['sleeves']} sleeves", f"{lk['legs']}, hair {lk['hair']}", extras]


# the part of render_rider_on_bike.py's picture the cyclist fills (fractions of its width and height)
CROP = (0.17, 0.2, 0.75, 0.73)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m bench.rider_looks_sheet", description=__doc__.splitlines()[0])
    p.add_argument("--bike", required=True, help="a bike folder with keypoints.json and bike.blend")
    p.add_argument("--work", required=True, help="folder for the posed rider files and the pictures")
    p.add_argument("--out", required=True, help="the contact sheet .png")
    p.add_argument("--riders", help="comma list of roster ids (default: every anny roster rider)")
    p.add_argument("--size", type=int, default=500, help="pixels per Blender picture, before the crop to the cyclist (default 500)")
    p.add_argument("--samples", type=int, default=16, help="Cycles samples per picture (default 16)")
    p.add_argument("--cols", type=int, default=5)
    args = p.parse_args(argv)
    from cyclist_formats import checks
    checks.count("size", args.size, hi=4096)
    checks.count("samples", args.samples, hi=4096)
    checks.count("cols", args.cols, hi=64)
    for f in ("keypoints.json", "bike.blend"):
        if not os.path.isfile(os.path.join(args.bike, f)):
            raise UserError(f"--bike {args.bike}: no {f}")
    if not args.out.endswith(".png"):
        raise UserError(f"--out must end in .png, got {args.out}")
    from splatting.rider.roster import get_spec, load_rider, load_roster
    ids = [x.strip() for x in args.riders.split(",") if x.strip()] if args.riders else \
        [r["id"] for r in load_roster() if r.get("body", "anny") == "anny"]
    specs = [get_spec(i) for i in ids]  # an unknown id fails here, before any work
    keypoints = json.load(open(os.path.join(args.bike, "keypoints.json")))["keypoints"]
    os.makedirs(args.work, exist_ok=True)
    torch.set_num_threads(1)
    jobs = []
    for k, spec in enumerate(specs):
        png = os.path.join(args.work, f"{spec['id']}.png")
        jobs.append({"rider": os.path.join(args.work, f"{spec['id']}_posed.npz"), "out": png, "label": label(spec)})
        if os.path.isfile(png) or os.path.isfile(jobs[-1]["rider"]):
            continue
        rider = load_rider(spec["id"])
        verts, worst = posed_on_bike(rider, keypoints)
        W = np.zeros((len(verts), 24), np.float32)
        W[:, 0] = 1.0  # a posed snapshot: not for skinning
        rider_file.write_rider_file(jobs[-1]["rider"], verts, rider.faces.numpy(), rider.joints.numpy(), W,
                                    rider.colors.numpy(), {"id": spec["id"], "posed": "crank 0 on " + os.path.basename(args.bike)})
        print(f"posed {k + 1}/{len(specs)} {spec['id']} (worst IK residual {worst * 100:.2f} cm)", flush=True)
    render_on_bike(jobs, args.work, args.bike, args.size, args.samples)
    from PIL import Image
    tiles = []
    for j in jobs:
        im = Image.open(j["out"]).convert("RGB")
        w, h = im.size
        tiles.append(im.crop((int(CROP[0] * w), int(CROP[1] * h), int(CROP[2] * w), int(CROP[3] * h))))
    save_png(labelled_sheet(tiles, [j["label"] for j in jobs], args.cols, "white"), args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    main_with_errors(main, "rider_looks_sheet")

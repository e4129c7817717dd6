"""A contact sheet of an augmented KITTI set: per sample, the image with the inserted cyclists' visible
masks outlined and their 2D boxes (green; the frame's own labelled boxes thin grey, orange where the
insertion raised their `occluded`), and the LiDAR bird's-eye view (when the set has velodyne/): the
scan's real points grey, the inserted ones red, the inserted 3D boxes' footprints green.

    python -m splatting.dataset.frames.sheet DATASET OUT.png [--samples 0,3,5,7]
"""
import argparse
import json
import os

import numpy as np

from cyclist_formats.kitti_frame import parse_calib, parse_labels, read_velodyne, velo_to_rect
from splatting.dataset.kitti import corners

ROW_W, BEV = 828, 276  # image width in the sheet; the bird's-eye panel's side (px)
BEV_RANGE = (0.0, 50.0, -25.0, 25.0)  # rect z from, to; rect x from, to (m)
GREEN, GREY, ORANGE, RED = (60, 230, 90), (200, 200, 200), (255, 150, 40), (255, 40, 40)


def _bev(scan, n_added, T, rows_new, size=BEV):
    from PIL import Image, ImageDraw
    img = Image.new("RGB", (size, size), (18, 18, 22))
    d = ImageDraw.Draw(img)
    z0, z1, x0, x1 = BEV_RANGE

    def px(x, z):
        return (x - x0) / (x1 - x0) * (size - 1), (1 - (z - z0) / (z1 - z0)) * (size - 1)
    rect = scan[:, :3] @ T[:3, :3].T + T[:3, 3]
    n_real = len(scan) - n_added
    for pts, col in ((rect[:n_real], (110, 110, 120)), (rect[n_real:], RED)):
        ok = (pts[:, 2] > z0) & (pts[:, 2] < z1) & (pts[:, 0] > x0) & (pts[:, 0] < x1)
        for x, z in pts[ok][:, [0, 2]][:: 1 if col == RED else 3]:
            u, v = px(x, z)
            d.point((u, v), fill=col)
    for r in rows_new:
        c = corners(r["h"], r["w"], r["l"], (r["x"], r["y"], r["z"]), r["rotation_y"])[[0, 2], :4].T
        d.polygon([px(x, z) for x, z in c], outline=GREEN)
    u, v = px(0.0, 0.0)
    d.polygon([(u, v - 6), (u - 4, v), (u + 4, v)], fill=(255, 255, 255))  # the car
    return img


def sheet(dataset, out_png, samples=None):
    """Write the sheet; -> the sample indices drawn."""
    from PIL import Image, ImageDraw
    from pycocotools import mask as mu
    with open(os.path.join(dataset, "annotations.json")) as f:
        doc = json.load(f)
    cyc = next(c["id"] for c in doc["categories"] if c.get("key") == "cyclist")
    ims = doc["images"] if samples is None else [doc["images"][i] for i in samples]
    kt = os.path.join(dataset, "kitti", "training")
    have_bev = os.path.isdir(os.path.join(kt, "velodyne"))
    tiles = []
    for im in ims:
        i = im["id"] - 1
        rgb = np.asarray(Image.open(os.path.join(dataset, "images", im["file_name"])).convert("RGB")).copy()
        for a in doc["annotations"]:
            if a["image_id"] == im["id"] and a["category_id"] == cyc:
                m = mu.decode(a["segmentation"]).astype(bool)
                inner = m.copy()  # the mask's outline (a 1-px erosion removed), so the cyclist itself shows
                inner[1:] &= m[:-1]
                inner[:-1] &= m[1:]
                inner[:, 1:] &= m[:, :-1]
                inner[:, :-1] &= m[:, 1:]
                rgb[m & ~inner] = GREEN
        tile = Image.fromarray(rgb)
        d = ImageDraw.Draw(tile)
        rows = [r for r, _ in parse_labels(os.path.join(kt, "label_2", f"{i:06d}.txt"))]
        n_own = len(im["frame"]["occlusion_raised"])
        for r, (old, new, _) in zip(rows[:n_own], im["frame"]["occlusion_raised"]):
            if r["type"] != "DontCare":
                d.rectangle([r["x1"], r["y1"], r["x2"], r["y2"]], outline=ORANGE if new > old else GREY, width=1)
        for r in rows[n_own:]:
            d.rectangle([r["x1"], r["y1"], r["x2"], r["y2"]], outline=GREEN, width=2)
        s = ROW_W / tile.width
        tile = tile.resize((ROW_W, int(round(tile.height * s))), Image.BILINEAR)
        if have_bev and os.path.isfile(os.path.join(kt, "velodyne", f"{i:06d}.bin")):
            scan = read_velodyne(os.path.join(kt, "velodyne", f"{i:06d}.bin"))
            added = sum({a["instance"]: a.get("lidar_points", 0) for a in doc["annotations"]
                         if a["image_id"] == im["id"]}.values())  # the scan ends with the inserted points
            T = velo_to_rect(parse_calib(os.path.join(kt, "calib", f"{i:06d}.txt")))
            bev = _bev(scan, added, T, rows[n_own:], BEV).resize((tile.height, tile.height), Image.BILINEAR)
            row = Image.new("RGB", (ROW_W + tile.height + 4, tile.height), (0, 0, 0))
            row.paste(tile, (0, 0))
            row.paste(bev, (ROW_W + 4, 0))
            tile = row
        tiles.append(tile)
    W = max(t.width for t in tiles)
    out = Image.new("RGB", (W, sum(t.height + 4 for t in tiles) - 4), (0, 0, 0))
    y = 0
    for t in tiles:
        out.paste(t, (0, y))
        y += t.height + 4
    os.makedirs(os.path.dirname(os.path.abspath(out_png)), exist_ok=True)
    out.save(out_png, optimize=True)
    return [im["id"] - 1 for im in ims]


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m splatting.dataset.frames.sheet", description=__doc__.splitlines()[0])
    ap.add_argument("dataset")
    ap.add_argument("out")
    ap.add_argument("--samples", help="comma list of sample indices (default: all)")
    a = ap.parse_args(argv)
    if not os.path.isfile(os.path.join(a.dataset, "annotations.json")):
        raise SystemExit(f"sheet: error: {a.dataset} holds no annotations.json (a finished dataset)")
    try:
        samples = None if not a.samples else [int(x) for x in a.samples.split(",")]
    except ValueError:
        raise SystemExit(f"sheet: error: --samples wants a comma list of indices, got {a.samples!r}")
    with open(os.path.join(a.dataset, "annotations.json")) as f:
        n = len(json.load(f)["images"])
    bad = [i for i in samples or [] if not 0 <= i < n]
    if bad:
        raise SystemExit(f"sheet: error: sample {bad[0]} is not in the dataset (0..{n - 1})")
    sheet(a.dataset, a.out, samples)


if __name__ == "__main__":
    main()

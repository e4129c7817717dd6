"""Picture of a crossing cyclist (docs/sequences.md, "Wheels"): a street sequence drawn with only
crossings, every turn announced by an arm signal, a static camera; the cyclist is shown

1. signalling, at the last frame before its crossing turn (motion blur on);
2. crossing the camera's path side-on at the instant (exposure 0): sharp spokes;
3. the same frame with motion blur: the spinning wheel sub-parts blur, the frame does not;
4. (with --plain-bikes-root) the same frame and blur with a bike of the same spec trained without
   sub-parts: its spokes stand still in the wheel, only the bike's travel smears them;
and below, the front wheel of 2-4 close up: the tyre, round, smears along the travel either way;
the turning wheel's spokes smear into arcs about the hub, the still wheel's are copies of one
spoke pattern shifted along the travel.

    python -m bench.sequence_wheels_sheet --out docs/img/sequence_wheels.png \
        --bikes-root out/sp/bikes --riders-root out/demo/riders [--plain-bikes-root out/demo/bikes]
"""
import argparse
import math
import os
import sys

import numpy as np
import torch

from bench.sequence_signal_sheet import compose
from bench import save_png
from cyclist_formats.errors import UserError
from splatting.dataset import camera_presets
from splatting.dataset.config import resolve_assets, validate
from splatting.dataset.generate import Assets
from splatting.dataset.sequences.draw import draw_sequence
from splatting.dataset.sequences.render import make_frame

RIDER = "m_adult_average_185"


def config(bikes_root, riders_root, bike, rider, seed, exposure, subframes, scale):
    return resolve_assets(validate({
        "mode": "street", "seed": seed, "camera": {"preset": "nuscenes", "scale": scale}, "bikes": [bike],
        "bikes_root": bikes_root, "riders": [rider], "riders_root": riders_root,
        "synthetic_assets": "never", "count": 1, "appearance": {"enabled": True},
        "street": {"cyclists": [1, 1], "parked_bikes": [0, 0], "distance_m": [7, 11]},
        "sequence": {"enabled": True, "length": 40, "signal_share": 1.0, "exposure_s": exposure,
                     "blur_subframes": subframes, "speed_mps": [4, 6],
                     "manoeuvres": {"straight": 0, "turn_left": 0, "turn_right": 0, "cross": 1, "overtake": 0,
                                    "stop": 0, "start": 0, "swerve": 0},
                     "ego": {"motion": "static"}}}))


def find_crossing(cfg, sequences=40):
    """(sequence, signal frame, side-on crossing frame) of a crossing cyclist that signals before
    its turn and then crosses 6-14 m ahead, in view, at its most side-on frame."""
    spec = camera_presets.resolve(cfg.camera)
    best = None
    for s in range(sequences):
        sd = draw_sequence(cfg, s)
        for inst in sd["instances"]:
            if inst["manoeuvre"] != "cross":
                continue
            sig = [f for f, x in enumerate(inst.get("signal", [])) if x in ("left", "right")]
            cross = np.flatnonzero(inst["crossing"])
            if not sig or not len(cross):
                continue
            def view(f, near, far, share):
                x, z = inst["poses"][f][5], inst["poses"][f][7] - sd["ego_z"][f]
                return near < z < far and abs(spec["fx"] * -x / max(z, 0.1)) < share * spec["width"]

            seen = [f for f in sig if view(f, 4.0, 25.0, 0.4)]
            ok = [(abs(math.cos(math.radians(inst["poses"][f][3]))), int(f)) for f in cross if view(f, 6.0, 14.0, 0.3)]
            if ok and seen:
                side, f = max(ok)
                if best is None or side > best[0]:
                    best = (side, s, seen[-1], f)
    if best is None:
        raise UserError("no drawn sequence has a signalling crossing cyclist in view; try another --seed")
    return best[1:]


def crop(frame, pad=0.25):
    rgb, _, anns, _ = frame
    ann = [a for a in anns if a["category_id"] in (3, 4)][0]
    x, y, w, h = ann["bbox_amodal"]
    m = pad * max(w, h)
    H, W = rgb.shape[:2]
    return rgb[max(int(y - m), 0):min(int(y + h + m), H), max(int(x - m), 0):min(int(x + w + m), W)], ann


def wheel_crop(frame, ann):
    """The front wheel of a side-on cyclist: a square in the lower corner of its box it rides towards."""
    rgb = frame[0]
    x, y, w, h = ann["bbox_amodal"]
    s = 0.5 * w
    left = ann["velocity_world_mps"][0] > 0  # world +X is image-left (the camera looks along +Z)
    x0 = int(x - 0.03 * w) if left else int(x + w - s + 0.03 * w)
    y0 = int(y + h - s + 0.03 * w)
    H, W = rgb.shape[:2]
    return rgb[max(y0, 0):min(y0 + int(s), H), max(x0, 0):min(x0 + int(s), W)]


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.sequence_wheels_sheet", description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="PNG to write")
    ap.add_argument("--bikes-root", required=True, help="bikes with trained wheel sub-parts (e.g. out/sp/bikes)")
    ap.add_argument("--riders-root", required=True, help="rider avatars (e.g. out/demo/riders)")
    ap.add_argument("--plain-bikes-root", default=None, help="the same bike trained without sub-parts (optional 4th tile)")
    ap.add_argument("--bike", default="city_00")
    ap.add_argument("--rider", default=RIDER)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--exposure", type=float, default=0.04,
                    help="shutter time (s; at most 1 / 10 Hz): 40 ms turns a 5 m/s wheel by ~33 deg, moves the bike 20 cm")
    ap.add_argument("--subframes", type=int, default=15)
    ap.add_argument("--scale", type=float, default=1.0, help="nuScenes camera scale")
    ap.add_argument("--height", type=int, default=380, help="tile height in the sheet (px)")
    args = ap.parse_args(argv)
    if not args.out.lower().endswith(".png"):
        ap.error("--out must be a .png file")
    for root in (args.bikes_root, args.plain_bikes_root):
        if root is not None and not os.path.isdir(os.path.join(root, args.bike)):
            ap.error(f"no bike folder {os.path.join(root, args.bike)}")
    torch.set_num_threads(1)
    try:
        still = config(args.bikes_root, args.riders_root, args.bike, args.rider, args.seed, 0.0, args.subframes, args.scale)
        blur = config(args.bikes_root, args.riders_root, args.bike, args.rider, args.seed, args.exposure, args.subframes, args.scale)
        s, f_sig, f_cross = find_crossing(still)
        n = still["sequence"]["length"]
        print(f"sequence {s}: signal frame {f_sig}, crossing frame {f_cross}", file=sys.stderr)
        tiles, wheels = [], []
        for cfg, f in ((blur, f_sig), (still, f_cross), (blur, f_cross)):
            fr = make_frame(cfg, s * n + f, Assets(cfg))
            img, ann = crop(fr)
            print(f"frame {f}: signal {ann['signal']}, intention {ann['intention']}, "
                  f"speed {ann['speed_mps']:.2f} m/s, wheel {ann['wheel_rate_rad_s']:.1f} rad/s", file=sys.stderr)
            tiles.append(img)
            if f == f_cross:
                wheels.append(wheel_crop(fr, ann))
        if args.plain_bikes_root:
            plain = config(args.plain_bikes_root, args.riders_root, args.bike, args.rider, args.seed, args.exposure,
                           args.subframes, args.scale)
            fr = make_frame(plain, s * n + f_cross, Assets(plain))
            img, ann = crop(fr)
            tiles.append(img)
            wheels.append(wheel_crop(fr, ann))
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    top = compose([tiles], height=args.height)
    bottom = compose([wheels], height=args.height)
    W = max(top.shape[1], bottom.shape[1])
    sheet = np.full((top.shape[0] + bottom.shape[0], W, 3), 255, np.uint8)
    sheet[:top.shape[0], :top.shape[1]] = top
    sheet[top.shape[0]:, :bottom.shape[1]] = bottom
    save_png(sheet, args.out)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Picture of the arm signals and of motion blur (docs/sequences.md):

row 1: one cyclist seen from behind-left, 4.5 m ahead, showing each arm signal (none, left, right,
stop, one-handed; Cyclist.pose with signals);
row 2: a frame of a street sequence where a turning or crossing cyclist signals, cropped around
it: the instant (exposure 0) and the same frame with motion blur (the ego camera driving).

    python -m bench.sequence_signal_sheet --out docs/img/sequence_signal.png \
        --bikes-root out/demo/bikes --riders-root out/demo/riders [--bike city_00] [--exposure 0.05]
"""
import argparse
import os
import sys

import numpy as np
import torch
from PIL import Image

from bench import save_png
from cyclist_formats.errors import UserError
from cyclist_formats.instances import RIDER_ID
from splatting.cyclist.render import over
from splatting.cyclist.scene_render import render_scene, slot_boxes, union
from splatting.dataset import camera_presets
from splatting.dataset.config import resolve_assets, validate
from splatting.dataset.config_models import Camera
from splatting.dataset.generate import Assets
from splatting.dataset.sequences.draw import draw_sequence
from splatting.dataset.sequences.render import make_frame
from splatting.rider.ik.signals import SIGNALS

RIDER = "m_adult_average_185"
GREY = 0.82


def signal_row(cfg, bike, rider):
    """(H, W, 3) uint8 tiles of the five signals, cropped to one common box."""
    assets = Assets(cfg)
    cyc = assets.cyclist(bike, rider)
    pose = [60.0, 0.0, 0.0, -70.0, 0.0, 0.4, 0.0, 4.5]  # riding away, seen from behind-left
    P = torch.tensor([pose] * len(SIGNALS), dtype=torch.float64)
    frames = cyc.pose(P, signals=list(SIGNALS))
    spec = camera_presets.resolve(Camera(preset="nuscenes", pitch_deg=0.0, roll_deg=0.0, scale=1.0))
    cam = camera_presets.street_camera(spec)
    renders, boxes = [], []
    for fr in frames:
        slots = torch.where(fr.ids == RIDER_ID, 2, 1).long()
        g = fr.gaussians
        boxes.append(union(slot_boxes(g.means, g.scales, slots, 3, cam)))
        renders.append(render_scene(g, slots, 3, cam))
    u0 = min(b[0] for b in boxes)
    v0 = min(b[1] for b in boxes)
    u1 = max(b[0] + b[2] for b in boxes)
    v1 = max(b[1] + b[3] for b in boxes)
    sl = np.s_[v0:v1, u0:u1]
    return [over({"rgb": L["rgb"][sl], "alpha": L["alpha"][sl]}, np.full((v1 - v0, u1 - u0, 3), GREY, np.float32))
            for L in renders]


def find_signalling_frame(cfg, sequences=60):
    """(sequence, frame, track) of a signalling cyclist 4-20 m ahead and in view, in the middle of
    its signal, whose screen motion (of a point 1.2 m above its origin, over one frame) is largest."""
    spec = camera_presets.resolve(cfg.camera)
    best = None
    for s in range(sequences):
        sd = draw_sequence(cfg, s)
        for k, inst in enumerate(sd["instances"]):
            on = [f for f, x in enumerate(inst.get("signal", [])) if x in ("left", "right", "stop")]
            if not on:
                continue
            f = on[len(on) // 2]
            if not 0 < f < len(sd["ego_z"]) - 1:
                continue
            uv = []
            for g in (f - 1, f, f + 1):
                dz = inst["poses"][g][7] - sd["ego_z"][g]
                uv.append((spec["fx"] * -inst["poses"][g][5] / max(dz, 0.1), spec["fy"] * 1.2 / max(dz, 0.1), dz))
            dz = uv[1][2]
            if 4.0 < dz < 20.0 and abs(uv[1][0]) < 0.4 * spec["width"]:
                score = float(np.hypot(uv[2][0] - uv[0][0], uv[2][1] - uv[0][1]))
                if best is None or score > best[0]:
                    best = (score, s, f, k)
    if best is None:
        raise UserError("signal_sheet: no drawn sequence has a signalling cyclist in view; try another seed")
    return best[1:]


def sequence_row(cfg, exposure, subframes):
    s, f, k = find_signalling_frame(cfg)
    n = cfg.sequence.length
    still = make_frame(cfg, s * n + f, Assets(cfg))
    cfg_b = cfg.model_copy(update={"sequence": cfg.sequence.model_copy(update={"exposure_s": exposure,
                                                                               "blur_subframes": subframes})})
    blurred = make_frame(cfg_b, s * n + f, Assets(cfg_b))
    ann = [a for a in still[2] if a["instance"] == k + 1 and a["category_id"] in (3, 4)][0]
    x, y, w, h = ann["bbox_amodal"]
    m = 0.35 * max(w, h)
    H, W = still[0].shape[:2]
    x0, y0 = max(int(x - m), 0), max(int(y - m), 0)
    x1, y1 = min(int(x + w + m), W), min(int(y + h + m), H)
    return [still[0][y0:y1, x0:x1], blurred[0][y0:y1, x0:x1]], ann["signal"], ann["intention"]


def compose(rows, pad=6, height=260):
    """Rows of tiles scaled to a common height, stacked; -> uint8 image."""
    lines = []
    for tiles in rows:
        scaled = [np.asarray(Image.fromarray(t).resize((max(1, round(t.shape[1] * height / t.shape[0])), height),
                                                         Image.LANCZOS)) for t in tiles]
        W = sum(t.shape[1] for t in scaled) + pad * (len(scaled) + 1)
        line = np.full((height + 2 * pad, W, 3), 255, np.uint8)
        x = pad
        for t in scaled:
            line[pad:pad + height, x:x + t.shape[1]] = t
            x += t.shape[1] + pad
        lines.append(line)
    W = max(line.shape[1] for line in lines)
    out = np.full((sum(line.shape[0] for line in lines), W, 3), 255, np.uint8)
    y = 0
    for line in lines:
        out[y:y + line.shape[0], :line.shape[1]] = line
        y += line.shape[0]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.sequence_signal_sheet",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, help="PNG to write")
    ap.add_argument("--bikes-root", required=True, help="folder of bikes (e.g. out/demo/bikes)")
    ap.add_argument("--riders-root", required=True, help="folder of rider avatars (e.g. out/demo/riders)")
    ap.add_argument("--bike", default="city_00")
    ap.add_argument("--rider", default=RIDER)
    ap.add_argument("--exposure", type=float, default=0.1, help="shutter time of the blurred frame (s; at most 1 / 10 Hz)")
    ap.add_argument("--subframes", type=int, default=9)
    args = ap.parse_args(argv)
    if not args.out.lower().endswith(".png"):
        ap.error("--out must be a .png file")
    if not os.path.isdir(os.path.join(args.bikes_root, args.bike)):
        ap.error(f"no bike folder {os.path.join(args.bikes_root, args.bike)}")
    torch.set_num_threads(1)
    only = {m: 0.0 for m in ("straight", "overtake", "stop", "start", "swerve")}
    try:
        cfg = resolve_assets(validate({
            "mode": "street", "seed": 4, "camera": {"preset": "nuscenes", "scale": 0.5}, "bikes": [args.bike],
            "bikes_root": args.bikes_root, "riders": [args.rider], "riders_root": args.riders_root,
            "synthetic_assets": "auto", "count": 1, "appearance": {"enabled": True},
            "street": {"cyclists": [2, 3], "parked_bikes": [0, 0], "distance_m": [6, 20]},
            "sequence": {"enabled": True, "length": 40, "signal_share": 1.0, "blur_subframes": args.subframes,
                         "manoeuvres": dict(only, turn_left=1.0, turn_right=1.0, cross=1.0),
                         "ego": {"motion": "moving", "speed_mps": [8, 10]}}}))
        top = signal_row(cfg, args.bike, args.rider)
        print("signal tiles done", file=sys.stderr)
        bottom, sig, inten = sequence_row(cfg, args.exposure, args.subframes)
        print(f"sequence frame: signal {sig}, intention {inten}", file=sys.stderr)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    sheet = compose([top, bottom])
    save_png(sheet, args.out)
    print(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

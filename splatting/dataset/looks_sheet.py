"""Contact sheet of appearance variety: one cyclist (bike + rider, one pose) in N sampled looks
(appearance.draw_look for sample indices 0..N-1), rendered side-on in a grid.  With --accessories
the colours stay and the tiles are the rider's per-instance accessories instead (accessories.draw
for sample indices 0..N-1: helmet and backpack at share 0.5, every hair style), each as the dataset
renders it (the redressed rider's Gaussians at the same pose).

    python -m splatting dataset looks-sheet --out docs/img/rider_looks.png [--bike DIR] [--rider ID] [--accessories]

Without --bike a stand-in bike is built from the procedural generator's spec (keypoints only);
the rider is a trained avatar from --riders-root when one exists, else the mesh avatar.
"""
import os
import shutil
import sys
import tempfile

from PIL import Image
import numpy as np
import torch

from cyclist_formats.atomic import atomic_path
from cyclist_formats.instances import RIDER_ID
from splatting import paths
from splatting.cyclist import accessories, appearance
from splatting.cyclist.render import over
from splatting.cyclist.scene_render import render_scene, slot_boxes, union
from splatting.cyclist.look_defaults import HAIR_STYLES
from splatting.dataset import camera_presets
from splatting.dataset.config import resolve_assets, validate
from splatting.dataset.generate import Assets

# without --bike: keypoints + meta of the procedural generator's city bike 0 (spec.sample_spec("city", 0, 0);
# blend_assets/stand_in_bike/, checked against the generator by tests/test_layers.py) for stand-in Gaussians
STAND_IN_BIKE = "city_00"


def render_sheet(cfg, bike, rider, n=12, cols=4, log=print):
    """(H, W, 3) uint8 grid of n looks of one cyclist (cfg.appearance varies accessories: n draws of
    them, in the rider's own colours)."""
    torch.set_num_threads(1)
    assets = Assets(cfg)
    cyc = assets.cyclist(bike, rider)
    pose = [60.0, 4.0, 0.0, 180.0, 0.0, 0.0, 0.0, 5.0]  # side-on, riding towards image-right, 5 m ahead
    frame = cyc.pose(torch.tensor(pose, dtype=torch.float64))[0]
    spec = camera_presets.resolve(cfg.camera)  # nuscenes, level, full size (write_looks_sheet's config)
    cam = camera_presets.street_camera(spec)
    variants = []
    for i in range(n):
        if accessories.varies(cfg.appearance):
            worn = accessories.draw(cfg.appearance, cfg.seed, i, 0, assets.own(rider))
            key = assets.wearing(rider, worn)
            rot, root = assets.avatars[rider].last
            f = frame if key == rider else accessories.swap_rider(frame, assets.model(key)[0], rot, root)
            variants.append((f, None, np.ones(3), {}))
            log(f"accessories {i + 1}/{n}: {worn}")
        else:
            look, gain = appearance.draw_look(cfg.appearance, cfg.seed, i, 0)
            variants.append((frame, look, gain, assets.look_inputs(bike, rider, frame)))
    # one crop for every tile: the union of their boxes (an accessory changes the outline)
    boxes = [union(slot_boxes(f.gaussians.means, f.gaussians.scales, torch.where(f.ids == RIDER_ID, 2, 1).long(), 3, cam))
             for f, *_ in variants]
    u0, v0 = min(b[0] for b in boxes), min(b[1] for b in boxes)
    w, h = max(b[0] + b[2] for b in boxes) - u0, max(b[1] + b[3] for b in boxes) - v0
    tiles = []
    for i, (f, look, gain, inputs) in enumerate(variants):
        g = f.gaussians if look is None else appearance.apply_look(f.gaussians, f.ids, look, gain, **inputs)
        L = render_scene(g, torch.where(f.ids == RIDER_ID, 2, 1).long(), 3, cam)
        sl = np.s_[v0:v0 + h, u0:u0 + w]
        tiles.append(over({"rgb": L["rgb"][sl], "alpha": L["alpha"][sl]}, np.full((h, w, 3), 0.82, np.float32)))
        if look is not None:
            log(f"look {i + 1}/{n}")
    rows = -(-n // cols)
    pad = 6
    sheet = np.full((rows * (h + pad) + pad, cols * (w + pad) + pad, 3), 255, np.uint8)
    for i, t in enumerate(tiles):
        r, c = divmod(i, cols)
        sheet[pad + r * (h + pad):pad + r * (h + pad) + h, pad + c * (w + pad):pad + c * (w + pad) + w] = t
    return sheet


def write_looks_sheet(out, bike=None, rider="m_adult_average_185", riders_root="data/riders", count=12, seed=0,
                      log=lambda m: print(m, file=sys.stderr), accessories_only=False, scale=1.0):
    """The sheet of `count` looks of `rider` on `bike` (a bike folder; None: the stand-in) written to out
    (.png); accessories_only: `count` draws of per-instance accessories in the rider's own colours; scale:
    the camera's resolution scale (the tiles' size)."""
    appearance = ({"helmet_share": 0.5, "bag_share": 0.5, "hair_styles": list(HAIR_STYLES)} if accessories_only
                  else {"enabled": True, "keep_share": 0.0})
    with tempfile.TemporaryDirectory() as scratch:
        if bike:
            root, bike_id = os.path.dirname(os.path.abspath(bike)), os.path.basename(os.path.abspath(bike))
        else:
            root, bike_id = scratch, STAND_IN_BIKE
            shutil.copytree(os.path.join(paths.BLEND_ASSETS, "stand_in_bike", STAND_IN_BIKE), os.path.join(scratch, bike_id))
        cfg = resolve_assets(validate({"mode": "street", "camera": {"preset": "nuscenes", "scale": scale}, "seed": seed,
                                       "bikes": [bike_id], "bikes_root": root, "riders": [rider],
                                       "riders_root": riders_root, "appearance": appearance}))
        sheet = render_sheet(cfg, bike_id, rider, count, log=log)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with atomic_path(out) as tmp:
        Image.fromarray(sheet).save(tmp, format="PNG")
    return out

"""Contact sheet of appearance variety: one cyclist (bike + rider, one pose) in N sampled looks
(appearance.draw_look for sample indices 0..N-1), rendered side-on in a grid.

    python -m splatting dataset looks-sheet --out docs/img/rider_looks.png [--bike DIR] [--rider ID]

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
from splatting.cyclist import appearance
from splatting.cyclist.render import over
from splatting.cyclist.scene_render import render_scene, slot_boxes, union
from splatting.dataset import camera_presets
from splatting.dataset.config import resolve_assets, validate
from splatting.dataset.generate import Assets

# without --bike: keypoints + meta of the procedural generator's city bike 0 (spec.sample_spec("city", 0, 0);
# blend_assets/stand_in_bike/, checked against the generator by tests/test_layers.py) for stand-in Gaussians
STAND_IN_BIKE = "city_00"


def render_sheet(cfg, bike, rider, n=12, cols=4, log=print):
    """(H, W, 3) uint8 grid of n looks of one cyclist."""
    torch.set_num_threads(1)
    assets = Assets(cfg)
    cyc = assets.cyclist(bike, rider)
    pose = [60.0, 4.0, 0.0, 180.0, 0.0, 0.0, 0.0, 5.0]  # side-on, riding towards image-right, 5 m ahead
    frame = cyc.pose(torch.tensor(pose, dtype=torch.float64))[0]
    spec = camera_presets.resolve(cfg.camera)  # nuscenes, level, full size (write_looks_sheet's config)
    cam = camera_presets.street_camera(spec)
    slots = torch.where(frame.ids == RIDER_ID, 2, 1).long()
    g0 = frame.gaussians
    u0, v0, w, h = union(slot_boxes(g0.means, g0.scales, slots, 3, cam))
    inputs = assets.look_inputs(bike, rider, frame)
    tiles = []
    for i in range(n):
        look, gain = appearance.draw_look(cfg.appearance, cfg.seed, i, 0)
        g = appearance.apply_look(g0, frame.ids, look, gain, **inputs)
        L = render_scene(g, slots, 3, cam)
        sl = np.s_[v0:v0 + h, u0:u0 + w]
        tiles.append(over({"rgb": L["rgb"][sl], "alpha": L["alpha"][sl]}, np.full((h, w, 3), 0.82, np.float32)))
        log(f"look {i + 1}/{n}")
    rows = -(-n // cols)
    pad = 6
    sheet = np.full((rows * (h + pad) + pad, cols * (w + pad) + pad, 3), 255, np.uint8)
    for i, t in enumerate(tiles):
        r, c = divmod(i, cols)
        sheet[pad + r * (h + pad):pad + r * (h + pad) + h, pad + c * (w + pad):pad + c * (w + pad) + w] = t
    return sheet


def write_looks_sheet(out, bike=None, rider="m_adult_average_185", riders_root="data/riders", count=12, seed=0,
                      log=lambda m: print(m, file=sys.stderr)):
    """The sheet of `count` looks of `rider` on `bike` (a bike folder; None: the stand-in) written to out (.png)."""
    with tempfile.TemporaryDirectory() as scratch:
        if bike:
            root, bike_id = os.path.dirname(os.path.abspath(bike)), os.path.basename(os.path.abspath(bike))
        else:
            root, bike_id = scratch, STAND_IN_BIKE
            shutil.copytree(os.path.join(paths.BLEND_ASSETS, "stand_in_bike", STAND_IN_BIKE), os.path.join(scratch, bike_id))
        cfg = resolve_assets(validate({"mode": "street", "camera": {"preset": "nuscenes"}, "seed": seed,
                                       "bikes": [bike_id], "bikes_root": root, "riders": [rider],
                                       "riders_root": riders_root, "appearance": {"enabled": True,
                                                                                  "keep_share": 0.0}}))
        sheet = render_sheet(cfg, bike_id, rider, count, log=log)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with atomic_path(out) as tmp:
        Image.fromarray(sheet).save(tmp, format="PNG")
    return out

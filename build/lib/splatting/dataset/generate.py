"""One dataset sample as a pure function of (config, sample index).

All randomness comes from numpy's Generator seeded with [seed, index] and is drawn in a fixed
order (asset choice, pose, camera, background), and everything after that is single-threaded
torch on CPU, so a sample renders to the same bytes whenever and in whichever worker it runs.
That is what makes a killed-and-resumed run identical to an uninterrupted one.
"""
import json
import os

import numpy as np
import torch

from cyclist_formats.atomic import atomic_path, write_json
from splatting.bike.model import KEYPOINTS as BIKE_KEYPOINTS
from splatting.cyclist.assets import bike_dir, load_avatar, load_bike
from splatting.cyclist.compose import Cyclist
from splatting.cyclist.render import keypoint_visibility, orbit_camera, over, project_points, render_layers
from splatting.dataset.coco import instance
from splatting.dataset.config import POSE_KEYS


class Assets:
    """Per-process cache of loaded bikes and rider avatars."""

    def __init__(self, cfg, log=None):
        self.cfg, self.log = cfg, log
        self.bikes, self.avatars, self.cyclists = {}, {}, {}

    def cyclist(self, bike, rider):
        key = (bike, rider)
        if key not in self.cyclists:
            c = self.cfg
            if bike not in self.bikes:
                self.bikes[bike] = load_bike(bike_dir(bike, c["bikes_root"]), c["synthetic_assets"],
                                             c["synthetic_gaussians_per_part"], log=self.log)
            av = None
            if rider is not None:
                if rider not in self.avatars:
                    self.avatars[rider] = load_avatar(rider, c["riders_root"], c["synthetic_assets"],
                                                      c["rider_gaussians"], log=self.log)[0]
                av = self.avatars[rider]
            self.cyclists[key] = Cyclist(self.bikes[bike], av, c["ik_iterations"])
        return self.cyclists[key]


def draw(cfg, index):
    """The random choices of sample `index`: asset ids, pose (8,), camera and background params."""
    rng = np.random.default_rng([cfg["seed"], index])
    bike = cfg["bikes"][int(rng.integers(len(cfg["bikes"])))]
    rider = cfg["riders"][int(rng.integers(len(cfg["riders"])))] if cfg["mode"] == "cyclist" else None
    pose = [float(rng.uniform(*cfg["pose"][k])) for k in POSE_KEYS]
    v = cfg["views"]
    cam = {"azimuth_deg": float(rng.uniform(*v["azimuth_deg"])), "elevation_deg": float(rng.uniform(*v["elevation_deg"])),
           "distance_m": float(rng.uniform(*v["distance_m"])),
           "jitter": (rng.uniform(-1, 1, 3) * v["centre_jitter_m"]).tolist()}
    kind = cfg["backgrounds"]["kinds"][int(rng.integers(len(cfg["backgrounds"]["kinds"])))]
    bg_seed = int(rng.integers(2 ** 31))
    return {"bike": bike, "rider": rider, "pose": pose, "camera": cam, "background": {"kind": kind, "seed": bg_seed}}


def background(kind, seed, size):
    """(size, size, 3) float32 in [0, 1], generated from the seed (nothing downloaded)."""
    rng = np.random.default_rng(seed)
    if kind == "solid":
        return np.broadcast_to(rng.uniform(0, 1, 3).astype(np.float32), (size, size, 3)).copy()
    if kind == "gradient":
        a, b = rng.uniform(0, 1, 3), rng.uniform(0, 1, 3)
        ang = rng.uniform(0, 2 * np.pi)
        y, x = np.mgrid[0:size, 0:size] / max(size - 1, 1) - 0.5
        t = np.clip(x * np.cos(ang) + y * np.sin(ang) + 0.5, 0, 1)[..., None]
        return ((1 - t) * a + t * b).astype(np.float32)
    # noise: a few octaves of bilinearly upsampled random grids (value noise)
    img = np.zeros((size, size, 3))
    amp, total = 1.0, 0.0
    for cells in (4, 8, 16, 64):
        grid = rng.uniform(0, 1, (cells + 1, cells + 1, 3))
        c = np.linspace(0, cells, size)
        i0 = np.minimum(c.astype(int), cells - 1)
        f = (c - i0)[:, None]
        rows = grid[i0] * (1 - f[..., None]) + grid[i0 + 1] * f[..., None]  # (size, cells+1, 3)
        img += amp * (rows[:, i0] * (1 - f.T[..., None]) + rows[:, i0 + 1] * f.T[..., None])
        total += amp
        amp *= 0.5
    return (img / total).astype(np.float32)


def make_sample(cfg, index, assets):
    """Render sample `index` -> (rgb uint8 (H, W, 3), image record, list of annotations)."""
    d = draw(cfg, index)
    cyc = assets.cyclist(d["bike"], d["rider"])
    frame = cyc.pose(torch.tensor(d["pose"], dtype=torch.float64))[0]
    size = cfg["image_size"]
    g = frame.gaussians
    lo, hi = g.means.min(0).values, g.means.max(0).values
    centre = (0.5 * (lo + hi)).double() + torch.tensor(d["camera"]["jitter"], dtype=torch.float64)
    cam = orbit_camera(d["camera"]["azimuth_deg"], d["camera"]["elevation_deg"], d["camera"]["distance_m"],
                       centre.tolist(), size, cfg["views"]["focal_px"])
    L = render_layers(g, frame.ids, cam)
    bg = background(d["background"]["kind"], d["background"]["seed"], size)
    rgb = over(L, bg)

    kp_cfg = cfg["keypoints"]
    bk = np.array([frame.bike_keypoints.get(n, [np.nan] * 3) for n in BIKE_KEYPOINTS], dtype=np.float64)
    have = np.isfinite(bk).all(1)
    uv, z = project_points(np.nan_to_num(bk), cam)
    vis = keypoint_visibility(uv, z, L["alpha"], L["depth"], kp_cfg["tolerance_bike_m"]) * have
    anns = [instance((L["ids"] >= 1) & (L["ids"] <= 3), "bicycle", np.column_stack([uv, vis]))]
    if frame.rider_joints is not None:
        uvr, zr = project_points(frame.rider_joints, cam)
        visr = keypoint_visibility(uvr, zr, L["alpha"], L["depth"], kp_cfg["tolerance_rider_m"])
        anns.append(instance(L["ids"] == 4, "person", np.column_stack([uvr, visr])))
        anns.append(instance(L["ids"] >= 1, "cyclist"))
    anns = [a for a in anns if a is not None]
    image = {"id": index + 1, "file_name": f"{index:06d}.png", "width": size, "height": size,
             "bike": d["bike"], "rider": d["rider"], "pose": d["pose"], "pose_fields": list(POSE_KEYS),
             "camera": {"K": cam.K.tolist(), "R": cam.R.tolist(), "T": cam.T.tolist(), **{k: v for k, v in d["camera"].items() if k != "jitter"}},
             "background": d["background"]}
    if frame.ik is not None:
        image["ik"] = frame.ik
    return rgb, image, anns


def write_sample(cfg, index, out_dir, assets):
    """Render and store one sample: image first, then its shard (the shard marks it complete)."""
    from PIL import Image
    rgb, image, anns = make_sample(cfg, index, assets)
    img_path = os.path.join(out_dir, "images", image["file_name"])
    with atomic_path(img_path) as tmp:
        Image.fromarray(rgb).save(tmp, format="PNG", compress_level=cfg["png_compress_level"])
    write_json(os.path.join(out_dir, "shards", f"{index:06d}.json"), {"image": image, "annotations": anns}, indent=None)
    return index


def sample_done(out_dir, index):
    return (os.path.isfile(os.path.join(out_dir, "shards", f"{index:06d}.json"))
            and os.path.isfile(os.path.join(out_dir, "images", f"{index:06d}.png")))


def config_record(cfg):
    return json.loads(json.dumps(cfg))

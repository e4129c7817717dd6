"""Loading the two halves of a cyclist: a bike (BikeModel) and a rider avatar (RiderAvatar).

Trained assets are used when they exist: `<bike>/gaussians/<part>.ply` and
`<riders_root>/<rider_id>/{rider.ply, skinning.npz}`.  Where they do not (and `synthetic` allows
it) stand-ins are built that keep the whole pipeline runnable:
- synthetic bike: Gaussians sampled on tubes between the bike's keypoints and on wheel circles,
  each on the part the keypoints belong to (frame, steering, crank); colour from meta.json;
- mesh avatar: Gaussians on the rider mesh's vertices with the mesh's own skinning weights and
  vertex colours (an "untrained" avatar that follows LBS exactly like the mesh).
Both are deterministic (fixed seed), so datasets built on them are reproducible.
"""
import math
import os

import numpy as np
import torch

from cyclist_formats import bike_folder
from cyclist_formats.errors import UserError
from splatting.bike.model import BikeModel
from splatting.gaussians.container import Gaussians
from splatting.gaussians.sh import rgb_to_sh0
from splatting.rider.avatar import BARE_NAME, PLY_NAME, RiderAvatar, SKINNING_NAME
from splatting.rider.roster import load_rider

SYNTHETIC_MODES = ("auto", "always", "never")


def _gaussians(points, colours, scale_m, opacity=0.95):
    n = len(points)
    return Gaussians(
        means=torch.as_tensor(points, dtype=torch.float32),
        quats=torch.tensor([[1.0, 0.0, 0.0, 0.0]]).repeat(n, 1),
        log_scales=torch.full((n, 3), math.log(scale_m)),
        opacity_logits=torch.full((n,), math.log(opacity / (1 - opacity))),
        sh=rgb_to_sh0(torch.as_tensor(colours, dtype=torch.float32))[:, None, :])


def _tube(rng, a, b, n, radius):
    a, b = np.asarray(a, float), np.asarray(b, float)
    t = rng.random(n)[:, None]
    jitter = rng.normal(size=(n, 3)) * radius * 0.5
    return a + t * (b - a) + jitter


def _ring(rng, centre, radius, n, normal_axis=2, width=0.02):
    phi = rng.random(n) * 2 * math.pi
    pts = np.zeros((n, 3)) + np.asarray(centre, float)
    ax = [i for i in range(3) if i != normal_axis]
    pts[:, ax[0]] += radius * np.cos(phi)
    pts[:, ax[1]] += radius * np.sin(phi)
    pts += rng.normal(size=(n, 3)) * width * 0.5
    return pts


def synthetic_bike_parts(keypoints, meta, n_per_part=2000, seed=0):
    """{part: Gaussians} on keypoint-based shapes (canonical frame).  keypoints: name -> (3,)."""
    rng = np.random.default_rng(seed)
    k = {n: np.asarray(v, float) for n, v in keypoints.items()}
    dims = meta.get("dimensions", {}) if isinstance(meta, dict) else {}
    wheel_r = float(dims.get("wheel_diameter_m", 2 * k["front_axle"][1])) / 2
    colour = np.asarray((meta.get("spec", {}) or {}).get("frame_colour", [0.6, 0.1, 0.1]), float)
    colour = np.clip(colour * 2.0 + 0.1, 0, 1)  # linear -> brighter display colour
    tyre, metal = np.array([0.08, 0.08, 0.08]), np.array([0.7, 0.7, 0.72])
    shapes = {"frame": [], "steering": [], "crank": []}  # (weight, sampler, colour)
    if "seat" in k and "crank_axle" in k:
        shapes["frame"] += [(1, lambda n: _tube(rng, k["seat"], k["crank_axle"], n, 0.02), colour),
                            (1, lambda n: _tube(rng, k["seat"], k["rear_axle"], n, 0.015), colour),
                            (1, lambda n: _tube(rng, k["crank_axle"], k["rear_axle"], n, 0.015), colour),
                            (1.2, lambda n: _tube(rng, k["crank_axle"], k["steer_bottom"], n, 0.025), colour),
                            (1, lambda n: _tube(rng, k["seat"], k["steer_top"], n, 0.02), colour),
                            (0.5, lambda n: _tube(rng, k["seat"] + [-0.1, 0.02, 0], k["seat"] + [0.12, 0.02, 0], n, 0.04),
                             np.array([0.15, 0.1, 0.08]))]
    else:
        shapes["frame"] += [(2, lambda n: _tube(rng, k["rear_axle"], k["steer_bottom"], n, 0.03), colour)]
    shapes["frame"] += [(4, lambda n: _ring(rng, k["rear_axle"], wheel_r, n), tyre)]
    mid_bar = 0.5 * (k["handle_left"] + k["handle_right"])
    shapes["steering"] += [(0.6, lambda n: _tube(rng, k["steer_top"], k["steer_bottom"], n, 0.025), colour),
                           (0.8, lambda n: _tube(rng, k["steer_bottom"], k["front_axle"], n, 0.015), metal),
                           (0.4, lambda n: _tube(rng, k["steer_top"], mid_bar, n, 0.015), metal),
                           (1.0, lambda n: _tube(rng, k["handle_left"], k["handle_right"], n, 0.012), metal),
                           (4, lambda n: _ring(rng, k["front_axle"], wheel_r, n), tyre)]
    if "pedal_left" in k:
        shapes["crank"] += [(1, lambda n: _tube(rng, k["crank_axle"], k["pedal_left"], n, 0.012), metal),
                            (1, lambda n: _tube(rng, k["crank_axle"], k["pedal_right"], n, 0.012), metal),
                            (0.6, lambda n: _tube(rng, k["pedal_left"] + [0, 0, -0.05], k["pedal_left"] + [0, 0, 0.0], n, 0.02), tyre),
                            (0.6, lambda n: _tube(rng, k["pedal_right"], k["pedal_right"] + [0, 0, 0.05], n, 0.02), tyre),
                            (2, lambda n: _ring(rng, k["crank_axle"] + [0, 0, 0.06], 0.1, n, width=0.01), metal)]
    parts = {}
    for part, items in shapes.items():
        if not items:
            continue
        w = np.array([i[0] for i in items], float)
        counts = np.maximum(1, np.round(n_per_part * w / w.sum()).astype(int))
        pts = np.concatenate([fn(c) for (_, fn, _), c in zip(items, counts)])
        col = np.concatenate([np.repeat(c[None], n, 0) for (_, _, c), n in zip(items, counts)])
        parts[part] = _gaussians(pts, col, 0.012)
    return parts


def bike_dir(bike, bikes_root):
    """A bike given as a folder or an id under bikes_root."""
    d = bike if os.path.isdir(bike) else os.path.join(bikes_root, bike)
    if not os.path.isdir(d):
        raise UserError(f"no bike folder {bike!r} (nor {d})")
    return d


def has_trained_gaussians(d):
    return all(os.path.isfile(os.path.join(d, "gaussians", p + ".ply")) for p in ("frame", "steering"))


def load_bike(d, synthetic="auto", n_per_part=2000, log=None):
    """BikeModel for folder d: trained Gaussians, or synthetic ones (see module docstring)."""
    if synthetic not in SYNTHETIC_MODES:
        raise UserError(f"synthetic must be one of {SYNTHETIC_MODES}, got {synthetic!r}")
    if synthetic != "always" and has_trained_gaussians(d):
        return BikeModel.load(d)
    if synthetic == "never":
        raise UserError(f"{d} has no trained Gaussians (gaussians/frame.ply, steering.ply); "
                        f"train them with `python -m splatting train` or allow synthetic bikes")
    kdoc = bike_folder.read_json(os.path.join(d, "keypoints.json"), "keypoints.json")
    meta = bike_folder.read_meta(d)
    parts = synthetic_bike_parts(kdoc["keypoints"], meta, n_per_part)
    if not meta.get("has_crank", True):
        parts.pop("crank", None)
    if log:
        log(f"bike {meta.get('bike_id')}: no trained Gaussians, using {sum(map(len, parts.values()))} "
            f"synthetic ones on its keypoint skeleton")
    return BikeModel(parts, kdoc, meta, source=d)


def mesh_gaussians(rider, idx, n_total=None):
    """Gaussians on the rider mesh's vertices idx with their colours, each as wide as the vertex
    spacing of n_total (default len(idx)) Gaussians spread over the skin, so the skin is closed."""
    area = 2.0 * rider.height_m ** 2 * 0.35  # ~1.9 m^2 skin for a 1.8 m adult (Du Bois order)
    scale = 0.8 * math.sqrt(area / (len(idx) if n_total is None else n_total))
    return _gaussians(rider.vertices[idx].numpy(), rider.colors[idx].numpy(), scale, opacity=0.98)


def mesh_avatar(rider, n=None, seed=0):
    """An untrained RiderAvatar: Gaussians on (a subset of) the rider mesh's vertices, with the
    vertex colours and skinning weights."""
    V = len(rider.vertices)
    idx = np.arange(V) if n is None or n >= V else np.sort(np.random.default_rng(seed).choice(V, n, replace=False))
    g = mesh_gaussians(rider, idx)
    return RiderAvatar(g, rider.weights[idx].clone(), rider.joints.clone(), rider.id, method="mesh_vertices")


def trained_avatar_folder(rider_id, riders_root, synthetic="auto", bare=False):
    """The folder of the rider's trained avatar that load_avatar takes, or None (it builds the mesh avatar);
    bare: of its accessory-free base (`rider-avatar --bare`, <folder>/bare/)."""
    folder = os.path.join(riders_root, rider_id, *([BARE_NAME] if bare else []))
    trained = all(os.path.isfile(os.path.join(folder, f)) for f in (PLY_NAME, SKINNING_NAME))
    return folder if synthetic != "always" and trained else None


def load_avatar(rider_id, riders_root="data/riders", synthetic="auto", n=None, log=None):
    """(RiderAvatar, rider body) for a roster id: trained avatar folder if present, else mesh_avatar."""
    rider = load_rider(rider_id)
    folder = trained_avatar_folder(rider_id, riders_root, synthetic)
    if folder is not None:
        return RiderAvatar.load(folder), rider
    folder = os.path.join(riders_root, rider_id)
    if synthetic == "never":
        raise UserError(f"no trained avatar in {folder}; build one with "
                        f"`python -m splatting rider-avatar --id {rider_id} --out {folder}`")
    av = mesh_avatar(rider, n)
    if log:
        log(f"rider {rider_id}: no trained avatar in {folder}, using {len(av)} Gaussians on its mesh")
    return av, rider

"""Backgrounds: generated ones (solid, gradient, value noise), the user's photos, a 3DGS scene, and
the soft contact shadows that keep cyclists from floating over photos and scenes.

- Generated: a function of the sample's background seed and the image size (nothing downloaded).
- `images`: JPG/PNG files of `backgrounds.images_dir` (listed, sorted, when the config is
  resolved, so the list is part of config.json and a resumed run sees the same files).  The
  sample's seed picks a file and a crop: the photo is scaled by the smallest factor that covers
  the image (aspect kept) and cropped at a random offset, so any photo size fits any camera.
- `scene`: an INRIA-layout 3DGS .ply (`backgrounds.scene_ply`: x, y, z, f_dc_*, f_rest_*,
  opacity, scale_*, rot_*; as the INRIA, gsplat and nerfstudio trainers write) moved into the
  street world by `backgrounds.scene_transform` (world = T(translation) Rz Ry Rx S(scale) ply,
  degrees and metres; put the road on Y = 0 with up = +Y).  Its Gaussians are rasterized together
  with the cyclists, so the scene hides what stands behind its objects.
- Contact shadows: a few flat, dark Gaussians on the road under each instance, elongated along its
  heading, composited with everything else (slot 0: they never enter an instance's mask).
"""
from dataclasses import replace
import functools
import math
import os

from PIL import Image
import numpy as np
import torch

from cyclist_formats.errors import UserError
from splatting.bike.pose import transform_gaussians
from splatting.gaussians.container import Gaussians, read_ply
from splatting.gaussians.sh import rgb_to_sh0

GENERATED = ("solid", "gradient", "noise")
IMAGE_EXTS = (".jpg", ".jpeg", ".png")


def generated(kind, seed, width, height):
    """(height, width, 3) float32 in [0, 1] from the seed."""
    rng = np.random.default_rng(seed)
    H, W = int(height), int(width)
    if kind == "solid":
        return np.broadcast_to(rng.uniform(0, 1, 3).astype(np.float32), (H, W, 3)).copy()
    if kind == "gradient":
        a, b = rng.uniform(0, 1, 3), rng.uniform(0, 1, 3)
        ang = rng.uniform(0, 2 * np.pi)
        y = np.arange(H) / max(H - 1, 1) - 0.5
        x = np.arange(W) / max(W - 1, 1) - 0.5
        # the ramp is a sum of a row and a column term: built by broadcasting, in float32
        t = (x[None, :] * np.cos(ang) + (y * np.sin(ang) + 0.5)[:, None]).astype(np.float32)
        np.clip(t, 0, 1, out=t)
        return a.astype(np.float32) + t[..., None] * (b - a).astype(np.float32)
    if kind != "noise":
        raise ValueError(f"not a generated background: {kind}")
    # a few octaves of bilinearly upsampled random grids (value noise). Bilinear upsampling is
    # separable: each octave's rows are interpolated on its small grid, and the columns of all
    # octaves at once by one (3, H, K) x (K, W) matmul with the column interpolation weights
    # (K = 96 grid columns in all). Measured 4 ms instead of 67-94 ms for per-octave full-size
    # gathers in float64, same values to 2e-7.
    amp, total = 1.0, 0.0
    rows, cols = [], []
    for cells in (4, 8, 16, 64):
        grid = rng.uniform(0, 1, (cells + 1, cells + 1, 3))
        cy, cx = np.linspace(0, cells, H), np.linspace(0, cells, W)
        iy, ix = np.minimum(cy.astype(int), cells - 1), np.minimum(cx.astype(int), cells - 1)
        fy, fx = (cy - iy)[:, None, None], cx - ix
        rows.append(amp * (grid[iy] * (1 - fy) + grid[iy + 1] * fy))  # (H, cells+1, 3)
        wx = np.zeros((W, cells + 1))
        wx[np.arange(W), ix] = 1 - fx
        wx[np.arange(W), ix + 1] += fx
        cols.append(wx)
        total += amp
        amp *= 0.5
    r = torch.from_numpy(np.concatenate(rows, 1).transpose(2, 0, 1) / total).float()  # (3, H, K)
    wx = torch.from_numpy(np.concatenate(cols, 1).T).float()  # (K, W)
    # torch, not numpy: it keeps to the worker's one thread (numpy's BLAS would start its own)
    return (r @ wx).permute(1, 2, 0).contiguous().numpy()


def list_images(folder, field="backgrounds.images_dir"):
    if not os.path.isdir(folder):
        raise UserError(f"config field '{field}': no such folder {folder!r}")
    files = sorted(f for f in os.listdir(folder) if f.lower().endswith(IMAGE_EXTS) and not f.startswith("."))
    if not files:
        raise UserError(f"config field '{field}': no .jpg/.jpeg/.png files in {folder!r}")
    return [os.path.join(folder, f) for f in files]


@functools.lru_cache(maxsize=8)
def _decoded(path, width, height):
    """The file decoded to RGB, by JPEG draft at 1/2..1/8 scale when that still covers width x
    height (the same pixels every time); cached per process: a folder of a few photos is decoded
    once per worker instead of once per sample.  -> (PIL image, source size)."""
    with Image.open(path) as im:
        w0, h0 = im.size
        s = max(width / w0, height / h0)
        im.draft("RGB", (max(int(w0 * s), width), max(int(h0 * s), height)))
        return im.convert("RGB"), (w0, h0)


def photo(files, seed, width, height):
    """(height, width, 3) uint8 (the photo's own bytes: no float round trip for the pixels no
    cyclist covers): one of the files, scaled to cover and cropped (from the seed); also returns
    {"file", "crop"} for the image record."""
    rng = np.random.default_rng(seed)
    path = files[int(rng.integers(len(files)))]
    fx, fy = float(rng.uniform()), float(rng.uniform())
    try:
        im, (w0, h0) = _decoded(path, int(width), int(height))
    except OSError as e:
        raise UserError(f"background image {path} cannot be read: {e}") from None
    w, h = im.size
    s = max(width / w, height / h)
    cw, ch = width / s, height / s
    x0, y0 = fx * (w - cw), fy * (h - ch)
    out = im.resize((int(width), int(height)), Image.BILINEAR, box=(x0, y0, x0 + cw, y0 + ch))
    rec = {"file": os.path.basename(path), "crop_xywh_source": [round(x0 * w0 / w, 2), round(y0 * h0 / h, 2),
                                                                round(cw * w0 / w, 2), round(ch * h0 / h, 2)]}
    return np.asarray(out, dtype=np.uint8), rec


def euler_matrix(rotation_deg):
    """Rz Ry Rx of (rx, ry, rz) degrees (the order of the bike pose's H_g)."""
    rx, ry, rz = (math.radians(a) for a in rotation_deg)
    Rx = np.array([[1, 0, 0], [0, math.cos(rx), -math.sin(rx)], [0, math.sin(rx), math.cos(rx)]])
    Ry = np.array([[math.cos(ry), 0, math.sin(ry)], [0, 1, 0], [-math.sin(ry), 0, math.cos(ry)]])
    Rz = np.array([[math.cos(rz), -math.sin(rz), 0], [math.sin(rz), math.cos(rz), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def load_scene(path, transform):
    """The 3DGS scene .ply in the street world (Gaussians); transform: the config's SceneTransform."""
    g = read_ply(path)
    s = float(transform.scale)
    H = np.eye(4)
    H[:3, :3] = euler_matrix(transform.rotation_deg)
    H[:3, 3] = transform.translation_m
    if s != 1.0:
        g = replace(g, means=g.means * s, log_scales=g.log_scales + math.log(s))
    return transform_gaussians(g, H)


def contact_shadows(footprints, opacity, n=5, sun=None, heights=None):
    """Flat dark Gaussians on the road: footprints = [(x, z, heading_deg, length_m, width_m)].

    sun (a relight Light; relit datasets, splatting/dataset/lighting.py) with heights [m] per
    footprint: the shadow is cast away from the sun -- the footprint's blobs repeated along the
    ground track of the instance's silhouette, from its wheels (height 0) to its top (height h
    shifted by h / tan(elevation), at most 4 h) -- and its darkness is the sun's share of the
    ground's light, E sin(el) / pi against the sky's L (what a shadow takes away), times opacity.
    An approximation (the silhouette is the footprint's), the same for every background."""
    means, quats, scales, opac = [], [], [], []
    o = min(max(opacity, 1e-4), 0.99)
    shift = np.zeros(2)
    if sun is not None:
        d = np.asarray(sun.direction(torch.float64))
        el = max(math.asin(min(1.0, d[1])), math.radians(1.0))
        lum = lambda c: float(np.dot(c, [0.2126, 0.7152, 0.0722]))  # noqa: E731
        e_sun = sun.sun_strength * lum(sun.sun_colour) * math.sin(el) / math.pi
        o = min(max(o * e_sun / (e_sun + lum(sun.sky) + 1e-9), 1e-4), 0.99)
        flat = np.array([d[0], d[2]])
        shift = -flat / max(np.linalg.norm(flat), 1e-9) / math.tan(el) if np.linalg.norm(flat) > 1e-6 else np.zeros(2)
    for i, (x, z, yaw, length, width) in enumerate(footprints):
        a = math.radians(yaw)
        fwd = np.array([math.cos(a), 0.0, -math.sin(a)])
        q = [math.cos(a / 2), 0.0, math.sin(a / 2), 0.0]  # about +Y: local x -> heading
        h = 0.0 if sun is None else float(heights[i])
        track = shift * h
        if np.linalg.norm(track) > 4 * h:
            track = track / np.linalg.norm(track) * 4 * h
        # copies ~0.35 footprint lengths apart, so about two overlap anywhere: each takes the opacity
        # whose double is o
        m = 1 + int(math.ceil(np.linalg.norm(track) / max(0.35 * length, 1e-3)))
        ob = o if m == 1 else 1.0 - math.sqrt(1.0 - o)
        for c in np.linspace(0.0, 1.0, m) if m > 1 else [0.0]:
            centre = np.array([x, 0.004, z])
            if c:
                centre = centre + np.array([c * track[0], 0.0, c * track[1]])
            for t in np.linspace(-0.5, 0.5, n):
                means.append(centre + t * 0.7 * length * fwd)
                quats.append(q)
                scales.append([0.45 * length / n * 1.6, 0.002, 0.35 * width])
                opac.append(ob)
    if not means:
        return None
    k = len(means)
    return Gaussians(means=torch.tensor(np.array(means), dtype=torch.float32),
                     quats=torch.tensor(quats, dtype=torch.float32),
                     log_scales=torch.log(torch.tensor(scales, dtype=torch.float32)),
                     opacity_logits=torch.tensor([math.log(p / (1 - p)) for p in opac], dtype=torch.float32),
                     sh=rgb_to_sh0(torch.full((k, 3), 0.03))[:, None, :])

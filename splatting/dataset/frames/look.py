"""Making the inserted pixels look like the frame's: light level and colour, the sensor's blur and noise.

- Light: the mean colour of the frame's road around the inserted instances (the pixels of their
  footprints grown by 1.5 m, below the horizon, outside every labelled box) against ROAD_REF, the
  road's value under the light the assets were trained in (a sunlit asphalt albedo of ~0.35 seen by
  a camera exposed for it).  exposure = luminance ratio, clamped to [0.6, 1.5] (part of a dark road
  is dark asphalt, not dim light: on the development frames the road's value spans 0.12-0.47 in
  equal sun); white balance =
  the road's chromaticity, each channel within +-15 % of grey (roads are grey: what differs is the
  light).  The gain multiplies the baked render (assets without relight channels, the default).
- Blur: the frame's optical blur sigma from its strong vertical edges (estimate_blur: for a Gaussian-
  blurred step of contrast C, the steepest one-pixel difference is C erf(1 / (2 sqrt(2) s)), solved
  for s per edge, median over the edges; on synthetic box-sampled steps blurred by 0.5, 0.8, 1.0 and
  1.5 px it reads 0.41, 0.77, 0.97 and 1.42, on KITTI's development frames 0.9-1.3), less the same
  estimate on the inserted render over grey (the rasterizer's own softness: s = sqrt(frame^2 -
  render^2)), applied to the inserted layers (premultiplied colour and alpha alike) with a separable
  Gaussian; or the config's sigma.
- Noise: the frame's noise sigma by Immerkaer's estimator (the Laplacian difference mask over the
  image, flat regions dominate its mean absolute response), added to the inserted pixels only in
  proportion to their alpha, from the sample's own seed.
Outside the blurred alpha the frame's bytes are untouched (tests check it).
"""
import math

import numpy as np

ROAD_REF = 0.35
LUMA = np.array([0.2126, 0.7152, 0.0722])
EXPOSURE = (0.6, 1.5)  # bounds of the exposure gain: roads differ in albedo too (fresh asphalt to paving)


def road_gain(image, road_mask):
    """(3,) gain from the road pixels of a uint8 image (road_mask (H, W) bool); ones when too few."""
    if road_mask.sum() < 50:
        return np.ones(3), None
    c = image[road_mask].astype(np.float64).mean(0) / 255.0
    lum = float(c @ LUMA)
    exposure = float(np.clip(lum / ROAD_REF, *EXPOSURE))
    wb = np.clip(c / max(lum, 1e-6), 0.85, 1.15)
    return exposure * wb, [round(float(x), 4) for x in c]


def estimate_blur(image, min_contrast=40.0, max_edges=4000):
    """Gaussian blur sigma (px) of a uint8 image from its strong horizontal steps (grey levels)."""
    g = image.astype(np.float64) @ LUMA if image.ndim == 3 else image.astype(np.float64)
    C = g[:, 6:] - g[:, :-6]  # the step's contrast, 3 px either side of the centre
    d = g[:, 3:-2] - g[:, 2:-3]  # one-pixel difference at the centre (same columns as C)
    d = d[:, :C.shape[1]]
    ok = (np.abs(C) >= min_contrast) & (np.sign(C) == np.sign(d)) & (np.abs(d) > 0)
    # the steepest difference of the step: a local maximum along the row
    dd = np.abs(g[:, 1:] - g[:, :-1])
    loc = np.zeros_like(ok)
    loc[:, :] = (dd[:, 2:2 + C.shape[1]] >= dd[:, 1:1 + C.shape[1]]) & (dd[:, 2:2 + C.shape[1]] >= dd[:, 3:3 + C.shape[1]])
    ok &= loc
    r = np.abs(d[ok]) / np.abs(C[ok])
    if r.size < 20:
        return None
    r = np.clip(r, 1e-3, 0.999)[::max(1, r.size // max_edges)]  # every k-th edge in raster order
    # r = erf(1 / (2 sqrt(2) s))  ->  s = 1 / (2 sqrt(2) erfinv(r))
    s = np.array([1.0 / (2 * math.sqrt(2) * _erfinv(x)) for x in r])
    return float(np.median(s))


def _erfinv(y):
    """erf^-1 on (0, 1) by Newton from Winitzki's approximation (no scipy)."""
    a = 0.147
    ln = math.log(1 - y * y)
    x = math.copysign(math.sqrt(math.sqrt((2 / (math.pi * a) + ln / 2) ** 2 - ln / a) - (2 / (math.pi * a) + ln / 2)), y)
    for _ in range(3):
        x -= (math.erf(x) - y) / (2 / math.sqrt(math.pi) * math.exp(-x * x))
    return x


def estimate_noise(image):
    """Noise sigma (in [0, 1] units) of a uint8 image: Immerkaer (1996), 'Fast noise variance estimation'."""
    g = (image.astype(np.float64) @ LUMA if image.ndim == 3 else image.astype(np.float64)) / 255.0
    H, W = g.shape
    conv = (g[:-2, :-2] - 2 * g[:-2, 1:-1] + g[:-2, 2:] - 2 * g[1:-1, :-2] + 4 * g[1:-1, 1:-1] - 2 * g[1:-1, 2:]
            + g[2:, :-2] - 2 * g[2:, 1:-1] + g[2:, 2:])
    return float(math.sqrt(math.pi / 2) * np.abs(conv).sum() / (6 * (W - 2) * (H - 2)))


def gaussian_kernel(sigma):
    r = max(1, int(math.ceil(3 * sigma)))
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return (k / k.sum()).astype(np.float32)


def blur(x, sigma):
    """Separable Gaussian blur of (h, w[, c]) float32 (edges padded by replication)."""
    if sigma <= 1e-3:
        return x
    k = gaussian_kernel(sigma)
    r = len(k) // 2
    pad = [(r, r), (0, 0)] + [(0, 0)] * (x.ndim - 2)
    y = np.pad(x, pad, mode="edge")
    x = sum(k[i] * y[i:i + x.shape[0]] for i in range(len(k)))
    pad = [(0, 0), (r, r)] + [(0, 0)] * (x.ndim - 2)
    y = np.pad(x, pad, mode="edge")
    return sum(k[i] * y[:, i:i + x.shape[1]] for i in range(len(k))).astype(np.float32)


def composite(frame, L, box, gain, sigma, noise, rng):
    """The frame (H, W, 3) uint8 with the inserted layers over it, inside box (u0, v0, w, h) grown
    by the blur's reach: gain on the colour, blur on colour and alpha, noise where alpha > 0.
    -> (image uint8, changed (H, W) bool)."""
    out = frame.copy()
    changed = np.zeros(frame.shape[:2], bool)
    if box is None:
        return out, changed
    H, W = frame.shape[:2]
    r = max(1, int(math.ceil(3 * sigma))) if sigma > 1e-3 else 0
    u0, v0, w, h = box
    u0, v0, u1, v1 = max(u0 - r, 0), max(v0 - r, 0), min(u0 + w + r, W), min(v0 + h + r, H)
    sl = np.s_[v0:v1, u0:u1]
    rgb = L["rgb"][sl] * np.asarray(gain, np.float32)
    a = L["alpha"][sl]
    if r:
        rgb, a = blur(np.ascontiguousarray(rgb), sigma), blur(np.ascontiguousarray(a), sigma)
    bg = frame[sl].astype(np.float32) / 255.0
    res = rgb + bg * (1.0 - a[..., None])
    if noise > 0:
        res = res + rng.normal(0.0, noise, res.shape).astype(np.float32) * np.minimum(a, 1.0)[..., None]
    m = a > 1e-4
    new = np.clip(res * 255.0 + 0.5, 0, 255).astype(np.uint8)
    out[sl] = np.where(m[..., None], new, frame[sl])
    changed[sl] = m
    return out, changed


def render_blur(L, box):
    """estimate_blur of the inserted layers over mid grey inside box (None: too few edges to tell)."""
    if box is None:
        return None
    u0, v0, w, h = box
    sl = np.s_[v0:v0 + h, u0:u0 + w]
    over = L["rgb"][sl] + 0.5 * (1.0 - L["alpha"][sl][..., None])
    return estimate_blur(np.clip(over * 255.0 + 0.5, 0, 255).astype(np.uint8))

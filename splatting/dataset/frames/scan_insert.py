"""Inserting posed Gaussian cyclists into a real Velodyne scan as the HDL-64E would see them
(docs/kitti_lidar.md).

Per cyclist (in the given order, each seeing the scan as the ones before left it):
1. Its angular box from the sensor: every Gaussian's direction +- its 3-sigma angular radius.
2. The rays: the beam model's lasers whose elevation falls in the box, at every azimuth firing
   in it: multiples of the azimuth step from each laser's own phase.  The phases are drawn
   uniformly in [0, step) per call (or all phase_deg): in KITTI's scans neighbouring lasers'
   firings are not aligned in azimuth (each laser has its own rotational correction), and a
   cyclist sampled on one grid for all lasers would show columns no real object shows.
3. A pinhole camera at the sensor origin aimed at the box's centre renders the cyclist with the
   project's rasterizer: alpha and the first surface's depth (camera z) per pixel
   (SurfaceLayers).  Its pixels are `pitch_m` (5 mm) wide at the cyclist's nearest Gaussian,
   about the 36-view ring's pixel at 12 m (5.8 mm), so each model's screen-space low-pass
   (eps2d, px^2) blurs it as in training, and the image is ~400 px whatever the distance; never
   coarser than max_pitch_deg (0.05 deg), a quarter of the beams' spacing.
4. Each ray reads its nearest pixel: alpha > 0.5 is a hit at range z / cos(angle to the axis),
   plus Gaussian range noise (range_noise_m, seeded).  The ray's cell (laser, azimuth firing) in
   the current scan: a point there nearer than the hit hides the cyclist on that ray (a wall or a
   car in front), and no point is added.
5. Every current point (real or inserted before) whose direction lies on the cyclist's
   silhouette (alpha > 0.5 at its pixel) farther than the cyclist's depth there is removed: the
   cyclist shadows it.
Added points get a reflectance drawn uniformly from `reflectance`, by default 0.14 - 0.53: the
10th - 90th percentiles of the 459 scan points inside the development frames' pedestrian and
cyclist boxes (more than 10 cm above their bottom; median 0.34; bench/lidar.py measures it).
Where a pixel's front surface is itself partly transparent (a thin tube before the rider's leg)
its depth window may mix in the surface behind: the hit lies between them.
"""
import math

import numpy as np
import torch

from splatting.dataset.frames import hdl64
from splatting.dataset.frames.lidar import _az_el_range, _transform
from splatting.raster.camera import Camera
from splatting.raster.api import EPS2D, rasterize

HIT_ALPHA = 0.5
REFLECTANCE = (0.14, 0.53)
MAX_IMAGE_PX = 4096  # a cyclist spanning a wide angle (very near): the pitch coarsens instead


def _per_cyclist(value, n, who):
    if isinstance(value, (list, tuple)):
        if len(value) != n:
            raise ValueError(f"insert_into_scan: {who} has {len(value)} entries for {n} cyclists")
        return list(value)
    return [value] * n


def _look_camera(origin, forward, up):
    """World(rect)-to-camera R (3, 3), T (3,) at origin looking along forward, image-up ~ up."""
    z = forward / np.linalg.norm(forward)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ origin


def _angular_box(g, T_rv):
    """(az_centre, az_half, el_lo, el_hi) (rad, velo) of a Gaussians' 3-sigma extent from the sensor."""
    m = g.means.detach().double().numpy() @ T_rv[:3, :3].T + T_rv[:3, 3]
    r = np.linalg.norm(m, axis=1)
    if (r < 0.5).any():
        raise ValueError("insert_into_scan: a cyclist reaches within 0.5 m of the sensor")
    s = 3.0 * g.scales.detach().double().max(1).values.numpy()
    ang = np.arcsin(np.clip(s / r, 0, 1))
    az, el, _ = _az_el_range(m)
    c = math.atan2(np.sin(az).mean(), np.cos(az).mean())
    daz = (az - c + math.pi) % (2 * math.pi) - math.pi
    # the horizontal angular radius grows as 1 / cos(elevation)
    aaz = ang / np.maximum(np.cos(el), 1e-3)
    return c, float(np.max(np.abs(daz) + aaz)), float(np.min(el - ang)), float(np.max(el + ang)), float(r.min())


def _cells(points, beams, phases):
    """(laser, azimuth firing, range) of velo points; phases (lasers,) rad."""
    az, el, rg = _az_el_range(points)
    L = beams.beam_index(el)
    return L, beams.azimuth_bin(az, phases[L]), rg


@torch.no_grad()
def render_from_sensor(g, T_velo_to_rect, az_c, az_half, el_lo, el_hi, pitch_deg, eps2d, antialiased):
    """The cyclist seen from the sensor: (R, T, K, alpha (H, W), depth_at) of a pinhole camera
    (world = rect) at the sensor origin aimed at the angular box's centre, covering the box;
    depth_at(rows, cols) -> the first surface's camera z at those pixels (SurfaceLayers.depth_at)."""
    T = T_velo_to_rect
    Rv, o = T[:3, :3], T[:3, 3]
    el_c = 0.5 * (el_lo + el_hi)
    fwd = Rv @ hdl64.directions(el_c, az_c)
    R, t = _look_camera(o, fwd, Rv @ np.array([0.0, 0.0, 1.0]))
    # the box's corners (and edge midpoints) in the camera: its extent in normalised coordinates
    azs = az_c + np.array([-az_half, 0.0, az_half])
    els = np.array([el_lo, el_c, el_hi])
    A, E = np.meshgrid(azs, els)
    d = (R @ Rv @ hdl64.directions(E.ravel(), A.ravel()).T).T
    if (d[:, 2] <= 0.05).any():
        raise ValueError("insert_into_scan: a cyclist spans too wide an angle from the sensor (> ~170 deg)")
    xn, yn = d[:, 0] / d[:, 2], d[:, 1] / d[:, 2]
    f = 1.0 / math.tan(math.radians(pitch_deg))
    span = max(xn.max() - xn.min(), yn.max() - yn.min())
    f = min(f, (MAX_IMAGE_PX - 8) / max(span, 1e-9))
    W = int(math.ceil(f * (xn.max() - xn.min()))) + 8
    H = int(math.ceil(f * (yn.max() - yn.min()))) + 8
    K = np.array([[f, 0, 4 - f * xn.min()], [0, f, 4 - f * yn.min()], [0, 0, 1]])
    cam = Camera(torch.tensor(R, dtype=torch.float32), torch.tensor(t, dtype=torch.float32),
                 torch.tensor(K, dtype=torch.float32), W, H, "lidar")
    layers = SurfaceLayers(g, cam, eps2d, antialiased)
    return R, t, K, layers.alpha, layers.depth_at


class SurfaceLayers:
    """The first surface along each pixel's ray: the depth where the accumulated alpha crosses
    HIT_ALPHA, not the expected depth of all Gaussians.  The
    rasterizer's expected depth leaks past an opaque surface: every Gaussian's alpha is capped at
    0.99 and a pixel between Gaussian centres keeps 1-2 % transmittance, so the far side of a
    cyclist pulls the depth of its near side back by centimetres (3.6 cm median on a 1.6 m box).
    Here each Gaussian's camera depth falls in one of up to max_bins bins (at least min_bin_m
    wide) and the rasterizer composites, per bin, the weights and weighted depths as feature
    channels; a pixel's depth is the weighted mean depth of the bin where the accumulated weight
    crosses HIT_ALPHA and its two neighbours (a surface split by a bin edge stays whole).
    alpha (H, W) numpy; depth_at(rows, cols) evaluates only the pixels asked for (rays and scan
    points: a few thousand of the image's ~10^5); depth() the whole image."""

    @torch.no_grad()
    def __init__(self, g, cam, eps2d=EPS2D, antialiased=False, max_bins=24, min_bin_m=0.05):
        self.w, self.wz, self.alpha = self._render(g, cam, eps2d, antialiased, max_bins, min_bin_m)

    @staticmethod
    def _render(g, cam, eps2d, antialiased, max_bins, min_bin_m):
        means = g.means.float()
        z = (means @ cam.R.float().T + cam.T.float())[:, 2]
        front = z > 0.01
        z0 = float(z[front].min()) if bool(front.any()) else 0.0
        z1 = float(z[front].max()) if bool(front.any()) else 1.0
        width = max(min_bin_m, (z1 - z0) / max_bins * (1 + 1e-6))
        B = max(1, min(max_bins, int(math.floor((z1 - z0) / width)) + 1))
        b = ((z - z0) / width).clamp(0, B - 1).long()
        onehot = torch.zeros(len(g), B)
        onehot[torch.arange(len(g)), b] = 1.0
        sh0 = torch.zeros(len(g), 1, 3)
        out = rasterize(means, g.quats.float(), g.scales.float(), g.opacities.float(), sh0, cam, sh_degree=0,
                        eps2d=eps2d, antialiased=antialiased, features=[onehot, onehot * z[:, None]], depth=False)
        f = out["features"]
        return f[..., :B], f[..., B:], out["alpha"].numpy()

    @staticmethod
    def _first(w, wz, a):
        """w, wz (..., B), a (...) -> the first surface's depth (...), 0 where alpha <= HIT_ALPHA."""
        B = w.shape[-1]
        cross = (torch.cumsum(w, -1) >= HIT_ALPHA).float()
        k = cross.argmax(-1)  # the first bin where the accumulated weight crosses (0 where none does)
        win = (torch.arange(B) - k[..., None]).abs() <= 1
        sw, swz = (w * win).sum(-1), (wz * win).sum(-1)
        return torch.where((a > HIT_ALPHA) & (sw > 1e-6), swz / sw.clamp_min(1e-6), torch.zeros_like(a))

    def depth_at(self, rows, cols):
        r, c = torch.as_tensor(rows, dtype=torch.long), torch.as_tensor(cols, dtype=torch.long)
        return self._first(self.w[r, c], self.wz[r, c], torch.from_numpy(self.alpha)[r, c]).numpy()

    def depth(self):
        return self._first(self.w, self.wz, torch.from_numpy(self.alpha)).numpy()


def _sample(R, K, alpha, depth_at, dirs_rect):
    """Nearest-pixel alpha and range (along the ray) for unit rect directions from the camera
    centre; alpha 0 outside the image or behind; the range only where alpha > HIT_ALPHA."""
    d = dirs_rect @ R.T
    H, W = alpha.shape
    front = d[:, 2] > 1e-6
    z = np.where(front, d[:, 2], 1.0)
    u = K[0, 0] * d[:, 0] / z + K[0, 2]
    v = K[1, 1] * d[:, 1] / z + K[1, 2]
    c, r = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    ok = front & (c >= 0) & (c < W) & (r >= 0) & (r < H)
    a = np.zeros(len(d), np.float32)
    rng = np.zeros(len(d))
    a[ok] = alpha[r[ok], c[ok]]
    on = np.nonzero(a > HIT_ALPHA)[0]
    rng[on] = depth_at(r[on], c[on]) / z[on]  # camera z -> range along the unit ray
    return a, rng


def insert_into_scan(scan, T_velo_to_rect, cyclists, eps2d=EPS2D, antialiased=False, rng=0, beams=None,
                     pitch_m=0.005, max_pitch_deg=0.05, range_noise_m=0.015, reflectance=REFLECTANCE,
                     phase_deg=None):
    """scan (N, 4) float32 velo (x, y, z, reflectance); cyclists: list of Gaussians posed in the
    rect frame; eps2d / antialiased: rasterize's, one for all or one per cyclist; rng: a numpy
    Generator or seed (the lasers' azimuth phases, range noise and reflectance); phase_deg: one
    azimuth phase for every laser instead of drawn ones.  -> (new_scan (M, 4) float32: the kept real
    points in their order, then the added points cyclist by cyclist; counts [points on each
    cyclist in new_scan]; removed (N,) bool: the real points the cyclists shadow)."""
    scan = np.asarray(scan)
    if scan.ndim != 2 or scan.shape[1] != 4 or not np.isfinite(scan).all():
        raise ValueError(f"insert_into_scan: scan must be a finite (N, 4) array, got shape {scan.shape}")
    T = _transform(T_velo_to_rect, "insert_into_scan")
    T_rv = np.linalg.inv(T)
    beams = beams or hdl64.HDL64E
    rng = np.random.default_rng(rng)
    n = len(cyclists)
    eps = _per_cyclist(eps2d, n, "eps2d")
    aas = _per_cyclist(antialiased, n, "antialiased")
    step = math.radians(beams.azimuth_step_deg)
    lasers = beams.elevations_rad()
    # drawn first: the same rng gives the same phases, noise and reflectances
    if phase_deg is None:
        phases = rng.uniform(0.0, step, len(lasers))
    else:
        phases = np.full(len(lasers), math.radians(phase_deg))
    Rv = T[:3, :3]

    pts = scan[:, :3].astype(np.float64)          # current points: real, then added
    refl = scan[:, 3].astype(np.float32)
    owner = np.full(len(scan), -1, np.int64)      # -1 real, j = cyclist j
    alive = np.ones(len(scan), bool)
    for j, g in enumerate(cyclists):
        if len(g) == 0:
            continue
        az_c, az_half, el_lo, el_hi, r_min = _angular_box(g, T_rv)
        pitch_deg = min(math.degrees(pitch_m / r_min), max_pitch_deg)
        R, t, K, alpha, depth_at = render_from_sensor(g, T, az_c, az_half, el_lo, el_hi, pitch_deg, eps[j], aas[j])

        # 5. shadowed points (before this cyclist's own points exist)
        idx = np.nonzero(alive)[0]
        p = pts[idx]
        rg = np.linalg.norm(p, axis=1)
        dirs = (p / np.maximum(rg, 1e-9)[:, None]) @ Rv.T
        a, r_c = _sample(R, K, alpha, depth_at, dirs)
        shadow = (a > HIT_ALPHA) & (rg > r_c)
        # 4. occluders of the rays: the nearest remaining point per (laser, firing) cell
        keep = idx[~shadow]
        lz, kz, rz = _cells(pts[keep], beams, phases)
        nearest = np.full(len(lasers) * beams.n_azimuth, np.inf)
        np.minimum.at(nearest, lz * beams.n_azimuth + kz, rz)
        alive[idx[shadow]] = False

        # 2. the rays in the angular box
        sel = np.nonzero((lasers >= el_lo) & (lasers <= el_hi))[0]
        k0 = math.floor((az_c - az_half) / step) - 1  # - 1, + 1: any phase in [0, step)
        k1 = math.ceil((az_c + az_half) / step)
        ks = np.arange(k0, k1 + 1)
        Lg, Kg = np.meshgrid(sel, ks, indexing="ij")
        Lg, Kg = Lg.ravel(), Kg.ravel()
        az = phases[Lg] + Kg * step
        dv = hdl64.directions(lasers[Lg], az)
        a, r_hit = _sample(R, K, alpha, depth_at, dv @ Rv.T)
        hit = np.nonzero((a > HIT_ALPHA) & (r_hit > 0))[0]
        kb = np.mod(Kg[hit], beams.n_azimuth)
        free = nearest[Lg[hit] * beams.n_azimuth + kb] > r_hit[hit]
        hit = hit[free]
        r_new = r_hit[hit] + rng.normal(0.0, range_noise_m, len(hit)) if range_noise_m > 0 else r_hit[hit]
        new = dv[hit] * r_new[:, None]
        pts = np.concatenate([pts, new])
        refl = np.concatenate([refl, rng.uniform(reflectance[0], reflectance[1], len(hit)).astype(np.float32)])
        owner = np.concatenate([owner, np.full(len(hit), j)])
        alive = np.concatenate([alive, np.ones(len(hit), bool)])

    removed = ~alive[:len(scan)]
    out = np.concatenate([pts[alive], refl[alive, None]], 1).astype(np.float32)
    # the real points keep their exact float32 values
    n_real = int((~removed).sum())
    out[:n_real] = scan[~removed]
    counts = [int(((owner == j) & alive).sum()) for j in range(n)]
    return out, counts, removed

"""The Velodyne HDL-64E of KITTI's car as a beam model: 64 elevation angles, the azimuth step at
10 Hz, the mounting height (docs/kitti_lidar.md).

Two elevation tables:
- NOMINAL_ELEVATIONS_DEG, the datasheet's layout approximated: an upper block of 32 lasers from
  +2.0 deg down in 1/3 deg steps and a lower block of 32 from -8.83 deg in 1/2 deg steps (to
  -24.33 deg; the datasheet gives a +2.0 / -24.9 deg field of view, the per-unit calibration
  spreads the angles).
- KITTI_ELEVATIONS_DEG, estimated from the ten development scans (estimate_beams()): a KITTI .bin
  stores the points laser by laser, each laser's sweep starting straight ahead, so the scan splits
  into 64 rings where the azimuth wraps past the forward direction; each ring's elevation is the
  median over its points beyond 5 m (when more than 10), and the table is the median over the
  scans (the lowest lasers reach 5 m in few scans: their entries rest on one to five).  It spans +2.60
  to -23.83 deg, upper block spacing 0.334 deg on average, lower 0.498 deg.  Ring elevations of the
  upper block vary by about 0.28 deg between scans (their points mix ranges where the lasers'
  offsets from the head's centre matter), the lower block's by under 0.1 deg.
The azimuth step, 0.180 deg (2000 firings a turn), is the median angle between consecutive points
of a ring in the same scans (quartiles 0.178 / 0.182 deg).
"""
import math
from dataclasses import dataclass

import numpy as np

NOMINAL_ELEVATIONS_DEG = tuple([2.0 - k / 3.0 for k in range(32)] + [-8.83 - k / 2.0 for k in range(32)])

KITTI_ELEVATIONS_DEG = (
    2.598, 2.172, 1.893, 1.439, 1.156, 0.749, 0.495, 0.158, -0.169, -0.577, -0.869, -1.218, -1.599, -1.946,
    -2.282, -2.634, -2.937, -3.32, -3.591, -3.959, -4.263, -4.593, -4.92, -5.239, -5.587, -5.902, -6.204,
    -6.466, -6.827, -7.17, -7.396, -7.765, -8.386, -8.903, -9.365, -9.751, -10.211, -10.812, -11.307,
    -11.729, -12.183, -12.606, -13.127, -13.648, -14.212, -14.65, -15.148, -15.508, -16.118, -16.642,
    -17.196, -17.646, -18.156, -18.556, -19.008, -19.558, -20.102, -20.719, -21.211, -21.759, -22.214,
    -22.961, -23.494, -23.827)

KITTI_AZIMUTH_STEP_DEG = 0.180
KITTI_SENSOR_HEIGHT_M = 1.73  # the Velodyne above the road (KITTI's sensor setup)


@dataclass(frozen=True)
class BeamModel:
    elevations_deg: tuple   # one per laser, top to bottom
    azimuth_step_deg: float
    height_m: float = KITTI_SENSOR_HEIGHT_M

    def __post_init__(self):
        el = np.asarray(self.elevations_deg, np.float64)
        if el.ndim != 1 or len(el) < 2 or not np.isfinite(el).all() or (np.diff(el) >= 0).any():
            raise ValueError("BeamModel: elevations_deg must be finite and strictly decreasing (top to bottom)")
        if not (0 < self.azimuth_step_deg < 10):
            raise ValueError(f"BeamModel: azimuth_step_deg {self.azimuth_step_deg} outside (0, 10)")

    @property
    def n_azimuth(self):
        return int(round(360.0 / self.azimuth_step_deg))

    def elevations_rad(self):
        return np.radians(np.asarray(self.elevations_deg, np.float64))

    def beam_index(self, elevation_rad):
        """Nearest laser (index into elevations_deg) of each elevation (rad): the cell boundaries
        lie halfway between neighbouring lasers."""
        el = self.elevations_rad()
        asc = el[::-1]
        mid = 0.5 * (asc[1:] + asc[:-1])
        k_asc = np.searchsorted(mid, np.asarray(elevation_rad, np.float64))
        return len(el) - 1 - k_asc

    def azimuth_bin(self, azimuth_rad, phase_rad=0.0):
        """Nearest firing (0 .. n_azimuth - 1) of each azimuth (rad)."""
        step = math.radians(self.azimuth_step_deg)
        return np.round((np.asarray(azimuth_rad, np.float64) - phase_rad) / step).astype(np.int64) % self.n_azimuth

    def azimuth_of_bin(self, k, phase_rad=0.0):
        a = phase_rad + np.asarray(k, np.float64) * math.radians(self.azimuth_step_deg)
        return (a + math.pi) % (2 * math.pi) - math.pi


HDL64E = BeamModel(KITTI_ELEVATIONS_DEG, KITTI_AZIMUTH_STEP_DEG)
HDL64E_NOMINAL = BeamModel(NOMINAL_ELEVATIONS_DEG, KITTI_AZIMUTH_STEP_DEG)


def directions(elevation_rad, azimuth_rad):
    """Unit ray directions (..., 3) in the velo frame (x forward, y left, z up)."""
    e, a = np.asarray(elevation_rad, np.float64), np.asarray(azimuth_rad, np.float64)
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1)


def split_rings(scan):
    """A KITTI scan in its file order -> list of index arrays, one per ring: a new ring starts
    where the azimuth wraps past straight ahead (x forward)."""
    p = np.asarray(scan, np.float64)
    az = np.degrees(np.arctan2(p[:, 1], p[:, 0])) % 360.0
    brk = np.where(np.diff(az) < -180.0)[0]
    return np.split(np.arange(len(p)), brk + 1)


def estimate_beams(scans, min_range_m=5.0, min_points=10):
    """(elevations_deg (64,) top to bottom, azimuth_step_deg, n_scans used) from KITTI scans in
    file order (see the module docstring).  Scans that do not split into 64 rings are skipped;
    ValueError if none does."""
    tables, steps = [], []
    for s in scans:
        p = np.asarray(s, np.float64)[:, :3]
        rings = split_rings(p)
        if len(rings) != 64:
            continue
        el = np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])))
        rg = np.linalg.norm(p, axis=1)
        az = np.degrees(np.arctan2(p[:, 1], p[:, 0])) % 360.0
        row = []
        for r in rings:
            far = r[rg[r] > min_range_m]
            row.append(float(np.median(el[far])) if len(far) > min_points else np.nan)
            d = np.diff(az[r])
            steps.append(d[(d > 0.12) & (d < 0.24)])  # neighbours, not gaps of missing returns
        tables.append(row)
    if not tables:
        raise ValueError("estimate_beams: no scan splits into 64 rings (not a KITTI HDL-64E scan in file order)")
    return np.nanmedian(np.array(tables), 0), float(np.median(np.concatenate(steps))), len(tables)

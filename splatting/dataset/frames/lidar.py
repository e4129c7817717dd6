"""LiDAR geometry of a KITTI frame: the road plane from the scan, ground support and obstacles under a
footprint, whether the sensor sees a spot or a nearer object shadows it, a dense depth image for
occlusion tests, and the points inside a labelled 3D box.  Pure numpy.

Frames (docs/kitti_lidar.md):
  velo: the Velodyne's own frame, x forward, y left, z up, origin at the sensor;
  rect: KITTI's rectified camera-0 frame, x right, y down, z forward.
  T_velo_to_rect (4, 4) = R0_rect (as 4x4) @ Tr_velo_to_cam (as 4x4): rect = T @ [velo, 1].
A plane (a, b, c, d) holds the rect points with a x + b y + c z + d = 0, as KITTI's / AVOD's
planes/*.txt write it: (a, b, c) a unit normal pointing up (b < 0, y is down), so d is the camera's
height above the road and a x + b y + c z + d is a point's height above it (e.g. 0 -1 0 1.65).
"""
import math

import numpy as np

from splatting.dataset.frames import hdl64


def _points(points_velo, who):
    p = np.asarray(points_velo)
    if p.ndim != 2 or p.shape[1] < 3:
        raise ValueError(f"{who}: points must be (N, 3) or (N, 4), got shape {p.shape}")
    p = p[:, :3].astype(np.float64)
    if not np.isfinite(p).all():
        raise ValueError(f"{who}: the points hold NaN or infinite values")
    return p


def _transform(T, who):
    T = np.asarray(T, np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise ValueError(f"{who}: T_velo_to_rect must be a finite (4, 4) matrix, got shape {T.shape}")
    return T


def velo_to_rect(points_velo, T_velo_to_rect):
    """(N, 3+) velo -> (N, 3) float64 rect."""
    p = _points(points_velo, "velo_to_rect")
    T = _transform(T_velo_to_rect, "velo_to_rect")
    return p @ T[:3, :3].T + T[:3, 3]


def rect_to_velo(points_rect, T_velo_to_rect):
    """(N, 3) rect -> (N, 3) float64 velo (the inverse of velo_to_rect, R0_rect included)."""
    p = _points(points_rect, "rect_to_velo")
    Ti = np.linalg.inv(_transform(T_velo_to_rect, "rect_to_velo"))
    return p @ Ti[:3, :3].T + Ti[:3, 3]


def sensor_origin_rect(T_velo_to_rect):
    """The Velodyne's origin in rect coordinates (3,)."""
    return _transform(T_velo_to_rect, "sensor_origin_rect")[:3, 3].copy()


def normalise_plane(plane):
    """(a, b, c, d) -> the same plane with a unit normal pointing up (b < 0): the planes-file sign."""
    p = np.asarray(plane, np.float64).reshape(-1)
    if p.shape != (4,) or not np.isfinite(p).all():
        raise ValueError(f"plane must be 4 finite numbers (a, b, c, d), got {plane!r}")
    n = np.linalg.norm(p[:3])
    if n < 1e-9:
        raise ValueError(f"plane normal is zero: {plane!r}")
    p = p / n
    return -p if p[1] > 0 else p


def plane_height(points_rect, plane):
    """Signed height (N,) of rect points above the plane (positive above the road)."""
    p = normalise_plane(plane)
    return np.asarray(points_rect, np.float64) @ p[:3] + p[3]


def plane_tilt_deg(plane):
    """Angle between the plane's normal and rect up (0, -1, 0), degrees."""
    p = normalise_plane(plane)
    return math.degrees(math.acos(min(1.0, -p[1])))


def _plane_from_inliers(pts):
    """Least-squares plane through pts (total least squares: the centroid and the smallest
    singular vector), oriented up."""
    c = pts.mean(0)
    _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
    n = vt[-1]
    return normalise_plane(np.r_[n, -n @ c])


def fit_ground_plane(points_velo, T_velo_to_rect, rng, iterations=200, inlier_m=0.08, max_tilt_deg=15.0,
                     height_range=(1.0, 2.5), max_range_m=40.0, min_points=200, score_points=5000):
    """The road plane (a, b, c, d) in rect coordinates (planes-file sign, unit normal up) from a scan.

    Candidates: points in front of the camera (rect z > 0), within max_range_m horizontally, whose
    height below the camera lies within height_range widened by 1 m (the road below the sensor;
    walls, cars and trees above it are mostly left out here and all of them by the RANSAC).
    RANSAC: `iterations` random triples (rng: a numpy Generator or a seed) give planes; those
    tilted more than max_tilt_deg from level or with a camera height outside height_range are
    discarded; the plane with most candidates within inlier_m (counted on at most score_points
    of them) wins.  Then three least-squares refits on its inliers among all candidates.
    ValueError (one message) when no plausible plane is found: too few candidates or inliers, or a
    refit that leaves the tilt / height limits."""
    rng = np.random.default_rng(rng)
    rect = velo_to_rect(points_velo, T_velo_to_rect)
    lo, hi = float(height_range[0]), float(height_range[1])
    keep = ((rect[:, 2] > 0) & (np.hypot(rect[:, 0], rect[:, 2]) < max_range_m)
            & (rect[:, 1] > lo - 1.0) & (rect[:, 1] < hi + 1.0))
    cand = rect[keep]
    if len(cand) < min_points:
        raise ValueError(f"fit_ground_plane: only {len(cand)} scan points below the sensor in front of the "
                         f"camera (need {min_points}): no road plane")
    score = cand if len(cand) <= score_points else cand[rng.choice(len(cand), score_points, replace=False)]
    tri = cand[rng.integers(0, len(cand), size=(iterations, 3))]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-9
    n = n[ok] / norm[ok, None]
    n[n[:, 1] > 0] *= -1  # up: b < 0
    d = -np.einsum("ij,ij->i", n, tri[ok, 0])
    cos_max = math.cos(math.radians(max_tilt_deg))
    ok = (-n[:, 1] >= cos_max) & (d >= lo) & (d <= hi)
    if not ok.any():
        raise ValueError(f"fit_ground_plane: no level plane {lo}-{hi} m below the camera among "
                         f"{iterations} RANSAC samples: no road plane")
    n, d = n[ok], d[ok]
    counts = (np.abs(score @ n.T + d) < inlier_m).sum(0)
    best = int(np.argmax(counts))
    plane = np.r_[n[best], d[best]]
    for _ in range(3):
        inl = cand[np.abs(cand @ plane[:3] + plane[3]) < inlier_m]
        if len(inl) < min_points:
            raise ValueError(f"fit_ground_plane: the best plane holds only {len(inl)} points within "
                             f"{inlier_m} m (need {min_points}): no road plane")
        plane = _plane_from_inliers(inl)
    tilt = plane_tilt_deg(plane)
    if tilt > max_tilt_deg or not lo <= plane[3] <= hi:
        raise ValueError(f"fit_ground_plane: the fitted plane is tilted {tilt:.1f} deg at {plane[3]:.2f} m below "
                         f"the camera (limits {max_tilt_deg} deg, {lo}-{hi} m): no plausible road plane")
    return plane


# --- footprints -------------------------------------------------------------------------------

def points_in_polygon(xy, poly):
    """(K, 2) points, (M, 2) polygon vertices (any orientation, not self-intersecting) -> (K,) bool
    (even-odd rule; points on an edge may go either way)."""
    xy, poly = np.asarray(xy, np.float64), np.asarray(poly, np.float64)
    x, y = xy[:, :1], xy[:, 1:2]
    a, b = poly, np.roll(poly, -1, axis=0)
    cross = (a[:, 1] > y) != (b[:, 1] > y)  # (K, M): the edge straddles the point's horizontal line
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return ((cross & (x < xi)).sum(1) % 2) == 1


def distance_to_polygon(xy, poly):
    """(K,) distance of each point to the polygon's boundary."""
    xy, poly = np.asarray(xy, np.float64), np.asarray(poly, np.float64)
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(((xy[:, None] - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0, 1)
    closest = a + t[..., None] * ab
    return np.linalg.norm(xy[:, None] - closest, axis=-1).min(1)


def in_footprint(xy, poly, margin=0.0):
    """Inside the polygon, or within margin of it (the footprint grown by margin)."""
    inside = points_in_polygon(xy, poly)
    if margin > 0 and len(xy):
        inside |= distance_to_polygon(xy, poly) <= margin
    return inside


def _footprint(footprint_xz, who):
    f = np.asarray(footprint_xz, np.float64)
    if f.ndim != 2 or f.shape[1] != 2 or len(f) < 3 or not np.isfinite(f).all():
        raise ValueError(f"{who}: footprint_xz must be a finite (M >= 3, 2) polygon in rect x, z, got shape {f.shape}")
    return f


OBSTACLE_M = (0.3, 2.5)  # a scan point this high above the road (m) inside a footprint: something stands there


def ground_support(points_velo, T_velo_to_rect, plane, footprint_xz, margin=0.5, ground_tol_m=0.15,
                   obstacle_m=OBSTACLE_M):
    """What the scan shows at a footprint (polygon in rect x, z on the road):
    ground = points within ground_tol_m of the plane inside the footprint grown by margin (the
    road around the spot: a cyclist must stand on seen ground), obstacle = points obstacle_m[0] to
    obstacle_m[1] above the plane inside the footprint itself (something already stands there)."""
    f = _footprint(footprint_xz, "ground_support")
    rect = velo_to_rect(points_velo, T_velo_to_rect)
    h = plane_height(rect, plane)
    # a cheap box test first: only points near the footprint's bounding box go to the polygon test
    lo, hi = f.min(0) - margin, f.max(0) + margin
    near = (rect[:, 0] >= lo[0]) & (rect[:, 0] <= hi[0]) & (rect[:, 2] >= lo[1]) & (rect[:, 2] <= hi[1])
    r, hn = rect[near], h[near]
    xz = r[:, [0, 2]]
    g = (np.abs(hn) < ground_tol_m) & in_footprint(xz, f, margin)
    o = (hn > obstacle_m[0]) & (hn < obstacle_m[1]) & in_footprint(xz, f, 0.0)
    return {"ground": int(g.sum()), "obstacle": int(o.sum())}


def _az_el_range(p):
    """velo points (N, 3) -> azimuth (rad, (-pi, pi]), elevation (rad), range (m) from the sensor."""
    return np.arctan2(p[:, 1], p[:, 0]), np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])), np.linalg.norm(p, axis=1)


def shadow_blockers(points_velo, T_velo_to_rect, plane, spots_rect, cone_deg=(0.5, 1.0), min_height_m=0.3,
                    gap_m=0.5):
    """(K,) number of scan points that shadow each rect spot from the sensor: points within the
    angular cone (azimuth, elevation half-widths cone_deg, about one beam's spacing) around the
    sensor->spot direction, nearer than the spot by more than gap_m, and more than min_height_m
    above the road (ground points in the cone are not blockers).  0 = the LiDAR sees the spot (or
    nothing in the scan stands in front of it)."""
    spots = np.asarray(spots_rect, np.float64).reshape(-1, 3)
    if not np.isfinite(spots).all():
        raise ValueError("shadow_blockers: spots_rect holds NaN or infinite values")
    p = _points(points_velo, "shadow_blockers")
    rect = velo_to_rect(p, T_velo_to_rect)
    high = plane_height(rect, plane) > min_height_m
    az, el, rg = _az_el_range(p[high])
    s_az, s_el, s_rg = _az_el_range(rect_to_velo(spots, T_velo_to_rect))
    da_max, de_max = math.radians(cone_deg[0]), math.radians(cone_deg[1])
    out = np.zeros(len(spots), np.int64)
    for k in range(len(spots)):
        da = np.abs((az - s_az[k] + math.pi) % (2 * math.pi) - math.pi)
        out[k] = int(((da <= da_max) & (np.abs(el - s_el[k]) <= de_max) & (rg < s_rg[k] - gap_m)).sum())
    return out


def visible_ground(points_velo, T_velo_to_rect, plane, spots_rect, **kw):
    """(K,) bool: the LiDAR sees each spot (no nearer object above the road in its direction:
    shadow_blockers == 0)."""
    return shadow_blockers(points_velo, T_velo_to_rect, plane, spots_rect, **kw) == 0


# --- depth image ------------------------------------------------------------------------------

def project_to_image(points_velo, T_velo_to_rect, P2, width, height, min_depth_m=0.5):
    """Scan points -> (rows, cols, depth rect z) of those in front of the camera inside the image
    (pixel (col, row) holds u in [col, col + 1): KITTI's pixel centres at +0.5)."""
    rect = velo_to_rect(points_velo, T_velo_to_rect)
    P = np.asarray(P2, np.float64)
    if P.shape != (3, 4) or not np.isfinite(P).all():
        raise ValueError(f"project_to_image: P2 must be a finite (3, 4) matrix, got shape {P.shape}")
    rect = rect[rect[:, 2] > min_depth_m]
    uvw = rect @ P[:, :3].T + P[:, 3]
    u, v = uvw[:, 0] / uvw[:, 2], uvw[:, 1] / uvw[:, 2]
    c, r = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    ok = (c >= 0) & (c < width) & (r >= 0) & (r < height)
    return r[ok], c[ok], rect[ok, 2]


def sparse_depth(rows, cols, depth, width, height):
    """(H, W) float32: the nearest depth of the points falling in each pixel, 0 where none."""
    D = np.full(height * width, np.inf)
    np.minimum.at(D, rows * width + cols, depth)
    D[~np.isfinite(D)] = 0.0
    return D.reshape(height, width).astype(np.float32)


def _nearest_along(D, axis, max_gap):
    """For every pixel: depth and distance (pixels) of the nearest valid pixel before and after it
    along axis (itself counts), within max_gap (a number, or an array broadcasting against D:
    one reach per row); 0 / inf where none."""
    n = D.shape[axis]
    idx = np.arange(n).reshape((-1, 1) if axis == 0 else (1, -1))
    valid = D > 0
    before = np.maximum.accumulate(np.where(valid, idx, -1), axis=axis)
    after = np.flip(np.minimum.accumulate(np.flip(np.where(valid, idx, n), axis=axis), axis=axis), axis=axis)
    out = []
    for j in (before, after):
        ok = (j >= 0) & (j < n) & (np.abs(j - idx) <= max_gap)
        jj = np.clip(j, 0, n - 1)
        d = np.take_along_axis(D, jj, axis=axis)
        out.append((np.where(ok, d, 0.0), np.where(ok, np.abs(j - idx), np.inf)))
    return out


def _fill_axis(D, axis, max_gap, rel_tol):
    """Fill empty pixels from the nearest valid ones along axis within max_gap (each side): linear
    interpolation where both sides exist and agree within rel_tol (one surface), else the nearer
    side's depth (a depth edge stays where the samples put it, halfway, not fattened)."""
    (d0, g0), (d1, g1) = _nearest_along(D, axis, max_gap)
    both = (d0 > 0) & (d1 > 0)
    agree = both & (np.abs(d0 - d1) <= rel_tol * np.minimum(d0, d1))
    with np.errstate(invalid="ignore", divide="ignore"):
        interp = np.where(agree, (d0 * g1 + d1 * g0) / (g0 + g1), 0.0)
    nearest = np.where(g0 <= g1, np.where(d0 > 0, d0, d1), np.where(d1 > 0, d1, d0))
    out = np.where(agree, interp, nearest)
    out = np.where(D > 0, D, out)
    return out.astype(np.float32)


def row_gap_px(height, fy, cy, beams=None):
    """(H,) the vertical gap (pixels) between neighbouring beams' rows at each image row: the
    beam model's local elevation spacing seen through the camera (the sensor's parallax to the
    camera, ~0.3 m, is ignored: it moves rows by under a pixel beyond ~20 m)."""
    beams = beams or hdl64.HDL64E
    el = np.asarray(beams.elevations_deg, np.float64)
    v = np.arange(height) + 0.5
    ang = -np.degrees(np.arctan((v - cy) / fy))  # elevation of the row's ray (up positive)
    order = np.argsort(el)
    es = el[order]
    spacing = np.diff(es)
    mid = 0.5 * (es[1:] + es[:-1])
    k = np.clip(np.searchsorted(mid, ang), 0, len(spacing) - 1)
    sp = spacing[k]
    # rows between two beams of spacing sp degrees are fy * sp (rad) / cos^2 apart
    return fy * np.radians(sp) / np.cos(np.radians(ang)) ** 2


def densify_depth(D, fy, cy, beams=None, max_col_gap_px=3, rel_tol=0.1, min_row_gap_px=2.0):
    """Densify a sparse depth image (0 = none): first along each row (the azimuth step leaves
    gaps of about 2 px at KITTI's focal length), then along each column with a bound that grows
    with the beam model's row spacing at that row (row_gap_px: ~4 px for the upper block,
    ~6 px for the lower).  Each pass interpolates between two samples of one surface and, across
    a depth edge, takes the sample nearer in pixels (_fill_axis): the edge stays halfway between
    the samples instead of the foreground growing by the whole reach as under a min filter
    (bench/lidar.py measures both).  Outside the beams' rows (above the
    top beam, below the image's last beam row) nothing is invented: 0 stays unknown."""
    H, W = D.shape
    D1 = _fill_axis(D.astype(np.float64), 1, int(max_col_gap_px), rel_tol)
    gaps = np.ceil(np.maximum(row_gap_px(H, fy, cy, beams), min_row_gap_px))
    return _fill_axis(D1.astype(np.float64), 0, gaps[:, None], rel_tol)  # each row its own reach


def lidar_depth_image(points_velo, T_velo_to_rect, P2, width, height, beams=None, **kw):
    """(H, W) float32 depth (rect z, metres; 0 = unknown) of the frame from its scan: the points
    projected with P2, the nearest per pixel, then densify_depth (kw: its settings)."""
    r, c, z = project_to_image(points_velo, T_velo_to_rect, P2, width, height)
    D = sparse_depth(r, c, z, width, height)
    P = np.asarray(P2, np.float64)
    return densify_depth(D, P[1, 1], P[1, 2], beams, **kw)


# --- 3D boxes ---------------------------------------------------------------------------------

def in_box(points_rect, box):
    """(N,) bool: rect points inside a KITTI box (h, w, l, x, y, z, ry): (x, y, z) the bottom
    centre, l along the object's x (heading), w across, h up (-y), ry about rect y."""
    b = np.asarray(box, np.float64).reshape(-1)
    if b.shape != (7,) or not np.isfinite(b).all() or (b[:3] <= 0).any():
        raise ValueError(f"box must be (h, w, l, x, y, z, ry) with positive sizes, got {box!r}")
    h, w, l, x, y, z, ry = b
    d = np.asarray(points_rect, np.float64) - (x, y, z)
    c, s = math.cos(ry), math.sin(ry)
    # R_y(ry) maps the object's axes to rect: local = R_y^T d
    lx = c * d[:, 0] - s * d[:, 2]
    lz = s * d[:, 0] + c * d[:, 2]
    return (np.abs(lx) <= l / 2) & (np.abs(lz) <= w / 2) & (d[:, 1] <= 0) & (d[:, 1] >= -h)


def points_in_box(points_velo, T_velo_to_rect, box):
    """Number of scan points inside a KITTI 3D box (label convention, see in_box)."""
    return int(in_box(velo_to_rect(points_velo, T_velo_to_rect), box).sum())


def canonical_to_rect(plane, x, z, ry):
    """(4, 4) rigid transform from a cyclist's canonical frame (X forward, Y up, ground Y = 0,
    docs/contract.md) to rect: standing on the plane at rect (x, z), heading rotation_y = ry in
    KITTI's convention (ry = 0 faces rect +x; forward = (cos ry, 0, -sin ry)), its up the plane's
    normal (a tilted road tilts the cyclist with it: both tyres stay on it)."""
    p = normalise_plane(plane)
    up = p[:3]
    # forward in the plane, straight above / below KITTI's level heading (cos ry, 0, -sin ry): the
    # label's rotation_y stays exact on a slope
    c, s = math.cos(ry), -math.sin(ry)
    f = np.array([c, -(up[0] * c + up[2] * s) / up[1], s])
    f /= np.linalg.norm(f)
    right = np.cross(f, up)
    y = -(p[0] * x + p[2] * z + p[3]) / p[1]
    H = np.eye(4)
    H[:3, 0], H[:3, 1], H[:3, 2], H[:3, 3] = f, up, right, (x, y, z)
    return H

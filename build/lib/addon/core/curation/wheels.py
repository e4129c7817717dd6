"""Find the wheels: two large near-circular rings sharing a plane (numpy, no bpy).

A wheel candidate is a connected component that is flat (thin along one principal axis),
round (equal spread along the other two) and whose outline is a circle: the outermost point
in each of 36 angular sectors lies at nearly the same distance from the fitted centre.  That
holds for a tyre alone, a tyre fused with its rim, or a whole wheel with spokes and hub.
"""
from dataclasses import dataclass

import numpy as np

SECTORS = 36


@dataclass
class Ring:
    comp: int            # component index in the Soup
    centre: np.ndarray   # (3,) model units
    normal: np.ndarray   # (3,) unit
    radius: float        # outer radius (the tyre's outer diameter / 2)
    roundness: float     # std/mean of the sector maxima (0 = perfect circle)


def fit_circle_2d(xy):
    """Algebraic (Kasa) least-squares circle: (centre (2,), radius)."""
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    b = (xy ** 2).sum(1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    c = sol[:2]
    return c, float(np.sqrt(max(sol[2] + c @ c, 0.0)))


def ring_of(points, comp_index=-1, flat=0.35, round_ratio=0.8, max_roundness=0.1):
    """Ring fit of one component's vertices, or None if it is not a ring/disc outline."""
    pts = np.asarray(points, float)
    if len(pts) < 12:
        return None
    mu = pts.mean(0)
    w, v = np.linalg.eigh(np.cov((pts - mu).T, bias=True))
    sd = np.sqrt(np.maximum(w, 0))  # ascending
    if sd[2] <= 0 or sd[0] > flat * sd[2] or sd[1] < round_ratio * sd[2]:
        return None
    normal = v[:, 0]
    e1, e2 = v[:, 2], v[:, 1]
    xy = np.column_stack([(pts - mu) @ e1, (pts - mu) @ e2])
    c2, _ = fit_circle_2d(xy)
    d = xy - c2
    r = np.hypot(d[:, 0], d[:, 1])
    sector = ((np.arctan2(d[:, 1], d[:, 0]) + np.pi) / (2 * np.pi) * SECTORS).astype(int) % SECTORS
    if len(np.unique(sector)) < SECTORS:
        return None
    rmax = np.full(SECTORS, 0.0)
    np.maximum.at(rmax, sector, r)
    roundness = float(rmax.std() / rmax.mean())
    if roundness > max_roundness:
        return None
    centre = mu + c2[0] * e1 + c2[1] * e2
    return Ring(comp_index, centre, normal / np.linalg.norm(normal), float(r.max()), roundness)


def find_rings(soup, min_points=12):
    """All ring-like components of a Soup, largest radius first."""
    rings = []
    for c in soup.comps:
        if len(c.verts) < min_points:
            continue
        s = c.spread  # quick reject before the full fit: must be flat and round
        if s[0] <= 0 or s[2] > 0.35 * s[0] or s[1] < 0.8 * s[0]:
            continue
        r = ring_of(soup.P[c.verts], c.index)
        if r is not None:
            rings.append(r)
    return sorted(rings, key=lambda r: -r.radius)


def wheel_pair(rings, min_ratio=0.6, parallel=0.98, max_offset=0.3, max_roundness=0.03):
    """The two wheels: the pair of round rings (a toothed chainring is a ring, but not round) with the largest radii that are parallel, share a plane
    (centre offset along the normal < max_offset * radius) and do not overlap.  None if absent."""
    best, best_score = None, -1.0
    rings = [r for r in rings if r.roundness <= max_roundness]
    for i, a in enumerate(rings):
        for b in rings[i + 1:]:
            if min(a.radius, b.radius) < min_ratio * max(a.radius, b.radius):
                continue
            if abs(a.normal @ b.normal) < parallel:
                continue
            d = b.centre - a.centre
            along = abs(d @ a.normal)
            if along > max_offset * max(a.radius, b.radius):
                continue
            if np.linalg.norm(d - (d @ a.normal) * a.normal) < 0.95 * (a.radius + b.radius):
                continue
            score = a.radius + b.radius
            if score > best_score:
                best, best_score = (a, b), score
    return best

"""Canonical pose and scale from the wheels (numpy, no bpy).

Given the two wheel rings of a model in arbitrary orientation, units and up-axis:
- lateral axis Z: the wheels' common plane normal;
- ground: the line tangent to both tyres from below, so Y (up) is perpendicular to it; the
  "up" side is the one where the saddle and handlebar stick out beyond the tyres;
- forward X: the crank (chainring) sits nearer the rear wheel; failing that, the wide parts
  high up (the handlebar) sit in front of the wheelbase's middle;
- scale: the mean tyre diameter becomes `wheel_diameter` metres;
- origin: on the ground, below the crank axle, in the wheels' mid-plane.
The result is M, a 4x4 similarity taking model coordinates to canonical metres.
"""
from dataclasses import dataclass, field

import numpy as np

from ..contract import UserError
from .wheels import Ring


@dataclass
class Pose:
    M: np.ndarray                 # 4x4, canonical = M @ [model, 1]
    scale: float                  # metres per model unit
    front: Ring
    rear: Ring
    crank: Ring = None            # the chainring, or None if not found
    keep: np.ndarray = None       # bool per component: part of the bike assembly
    notes: list = field(default_factory=list)
    forward_cue: str = ""

    def apply(self, p):
        p = np.asarray(p, float)
        return p @ self.M[:3, :3].T + self.M[:3, 3]


def _unit(v):
    return v / np.linalg.norm(v)


def ground_like(soup, R):
    """Components that are flat sheets bigger than a wheel: ground planes, backdrops."""
    out = np.zeros(len(soup.comps), bool)
    for i, c in enumerate(soup.comps):
        s = c.spread
        if s[0] > 1.2 * R and s[2] < 0.01 * s[0]:
            out[i] = True
    return out


def assembly(soup, seeds, exclude, gap):
    """Components reachable from `seeds` through bounding boxes that touch (within gap)."""
    lo = np.array([c.bbox[0] for c in soup.comps]) - gap
    hi = np.array([c.bbox[1] for c in soup.comps]) + gap
    keep = np.zeros(len(soup.comps), bool)
    keep[list(seeds)] = True
    frontier = list(seeds)
    while frontier:
        f = np.array(frontier)
        # (F, N) overlap test of frontier boxes against all boxes
        ov = np.all((lo[None, :, :] <= hi[f][:, None, :]) & (hi[None, :, :] >= lo[f][:, None, :]), axis=2)
        new = np.where(ov.any(0) & ~keep & ~exclude)[0]
        keep[new] = True
        frontier = list(new)
    return keep


def canonical_pose(soup, rings, pair, wheel_diameter=0.7, seeds=None, front=None):
    a, b = pair
    R = 0.5 * (a.radius + b.radius)
    n = _unit(a.normal + np.sign(a.normal @ b.normal) * b.normal)
    ca = a.centre - ((a.centre - b.centre) @ n) / 2 * n  # both centres onto the mid-plane
    cb = b.centre + ((a.centre - b.centre) @ n) / 2 * n
    comp_pos = {c.index: i for i, c in enumerate(soup.comps)}
    ground = ground_like(soup, R)
    if seeds is None:
        seeds = [comp_pos[a.comp], comp_pos[b.comp]]
    keep = assembly(soup, seeds, ground, gap=0.02 * R)
    notes = []
    if ground.any():
        notes.append(f"removed {int(ground.sum())} ground/backdrop sheet(s)")
    dropped = int((~keep & ~ground).sum())
    if dropped:
        notes.append(f"removed {dropped} component(s) not attached to the bike")
    # vertices of the bike assembly
    P = soup.P[soup.vert_mask(keep)]
    D = cb - ca
    L = np.linalg.norm(D)
    d = D / L
    p = np.cross(n, d)
    # ground tangent to both tyres: its normal y satisfies y.(cb - ca) = rb - ra
    s_ = (b.radius - a.radius) / L
    c_ = np.sqrt(max(1 - s_ * s_, 0.0))
    ups = [_unit(s_ * d + c_ * p), _unit(s_ * d - c_ * p)]
    scores = []
    for y in ups:
        h = (P - ca) @ y
        scores.append(float(np.clip(h - 1.2 * R, 0, None).sum() - np.clip(-h - 1.2 * R, 0, None).sum()))
    y = ups[int(np.argmax(scores))]
    x0 = _unit(d - (d @ y) * y)  # from wheel a to wheel b, parallel to the ground
    z0 = np.cross(x0, y)
    scale = wheel_diameter / (2 * R)
    mid = 0.5 * (ca + cb)

    def local(q):  # model -> (x along a->b, height above ground, lateral) in metres
        q = np.asarray(q, float) - mid
        g = mid @ y - (ca @ y - a.radius)  # height of `mid` above the ground
        return np.stack([q @ x0, q @ y + g, q @ z0], -1) * scale

    # chainring: a ring parallel to the wheels, between them, well below wheel size
    crank = None
    xa, xb = local(ca)[0], local(cb)[0]
    for r in rings:
        if r.comp in (a.comp, b.comp) or abs(r.normal @ n) < 0.95:
            continue
        q = local(r.centre)
        rr = r.radius * scale
        if not (0.08 * wheel_diameter / 2 <= rr <= 0.5 * wheel_diameter / 2):
            continue
        if not (xa + 0.15 * (xb - xa) < q[0] < xa + 0.85 * (xb - xa)) or abs(q[2]) > 0.15:
            continue
        if q[1] > 1.5 * wheel_diameter / 2:
            continue
        if crank is None or r.radius > crank.radius:
            crank = r
    # forward: given (the annotator placed the front wheel), else the chainring sits nearer
    # the rear wheel, else the handlebar is ahead of the wheelbase middle
    sign, cue = 0, ""
    if front is not None:
        sign, cue = (1 if np.linalg.norm(front - cb) < np.linalg.norm(front - ca) else -1), "front wheel given"
    if crank is not None and sign == 0:
        xc = local(crank.centre)[0]
        da, db = abs(xc - xa), abs(xb - xc)
        if abs(da - db) > 0.1 * abs(xb - xa):
            sign, cue = (1 if da < db else -1), "chainring nearer the rear wheel"
    if sign == 0:
        q = local(P)
        wide = (q[:, 1] > 2.25 * wheel_diameter / 2) & (np.abs(q[:, 2]) > 0.12)
        if wide.sum() >= 4:
            xm = q[wide, 0].mean()
            if abs(xm) > 0.02:
                sign, cue = (1 if xm > 0 else -1), "handlebar in front of the wheelbase centre"
    if sign == 0:
        raise UserError("cannot tell the front of the bike from its back (no chainring or handlebar found); "
                        "give keypoints with --keypoints FILE.json")
    X = x0 * sign
    Z = np.cross(X, y)
    front, rear = (b, a) if sign > 0 else (a, b)
    # origin: on the ground below the crank axle (or 40% of the wheelbase ahead of the rear
    # axle when no chainring was found), in the wheels' mid-plane
    if crank is not None:
        oc = crank.centre
    else:
        cr = ca if rear is a else cb
        cf = cb if rear is a else ca
        oc = cr + 0.4 * (cf - cr)
        notes.append("no chainring found: crank_axle placed at 40% of the wheelbase; check it")
    oc = oc - ((oc - mid) @ n) * n
    ground_h = (oc - (ca if rear is a else cb)) @ y + rear.radius
    origin = oc - ground_h * y
    Rm = np.stack([X, y, Z])  # rows: canonical axes in model coordinates
    M = np.eye(4)
    M[:3, :3] = scale * Rm
    M[:3, 3] = -scale * Rm @ origin
    return Pose(M, scale, front, rear, crank, keep, notes, cue)

"""Automatic keypoints on a model already in the canonical pose (numpy, no bpy).

Conventions (how an annotator places them by hand too; docs/contract.md names):
- front_axle / rear_axle: wheel centres; ground: on the ground below the rear axle.
- crank_axle: the chainring centre, moved into the symmetry plane Z = 0.
- steer_top / steer_bottom: on the head tube's axis, 1 cm inside its ends.
- handle_left / handle_right: grip centres (middle of the grip tube); for drop bars the bar's
  centreline at the brake hood.
- pedal_left / pedal_right: centre of each pedal body.
- seat: 4 mm below the saddle's top surface at its mid-length.
Each estimator returns None when its part is not found; validate() then names the keypoint.
"""
import numpy as np

from ..procedural.layout import KEYPOINT_NAMES

HEAD_INSET = 0.01
SEAT_DEPTH = 0.004


class View:
    """The kept components of a Soup in canonical coordinates (metres)."""

    def __init__(self, soup, pose):
        self.soup = soup
        self.P = soup.transformed_points(pose.M)
        self.comps = [c for c, k in zip(soup.comps, pose.keep) if k]
        tri_c = self.P[soup.TW].mean(1)
        self.tri_c = tri_c
        self.area = soup.area * pose.scale ** 2

    def pts(self, c):
        return self.P[c.verts]

    def stats(self, c):
        """(centre, bbox lo, bbox hi, axes rows, spread) of a component, canonical."""
        p = self.pts(c)
        mu = p.mean(0)
        w, v = np.linalg.eigh(np.cov((p - mu).T, bias=True)) if len(p) >= 3 else (np.zeros(3), np.eye(3))
        o = np.argsort(w)[::-1]
        return mu, p.min(0), p.max(0), v[:, o].T, np.sqrt(np.maximum(w[o], 0))


def head_tube(view, front_axle, crank_axle):
    """(radius, bottom end point, top end point, unit axis up) of the head tube, or None.

    The head tube is the thickest tube through the plane of symmetry, in front of the crank,
    above the front axle, leaning back at 55-85 degrees from the ground."""
    best = None
    for c in view.comps:
        if len(c.verts) < 8:
            continue
        mu, lo, hi, ax, sd = view.stats(c)
        if sd[0] < 1.8 * sd[1] or sd[1] > 1.6 * max(sd[2], 1e-9):
            continue
        a = ax[0] if ax[0][1] > 0 else -ax[0]
        if abs(a[2]) > 0.15 or a[0] > 0 or not (55 <= np.degrees(np.arctan2(a[1], -a[0])) <= 85):
            continue
        if abs(mu[2]) > 0.02 or mu[1] < front_axle[1] or mu[0] < crank_axle[0] + 0.4 * (front_axle[0] - crank_axle[0]):
            continue
        p = view.pts(c)
        t = (p - mu) @ a
        rad = np.linalg.norm((p - mu) - np.outer(t, a), axis=1)
        r = float(np.median(rad))
        length = t.max() - t.min()
        if length < 0.06 or length > 0.4:
            continue
        # a head tube starts above the tyre: a piece reaching down into the front wheel (the
        # axle's height is the wheel's radius) is a fork blade or a fender stay, not it (a
        # decimated bicycle's coarse head tube failed the tube test and its fork won)
        bot = mu + t.min() * a
        if np.hypot(bot[0] - front_axle[0], bot[1] - front_axle[1]) < 0.9 * front_axle[1]:
            continue
        if best is None or r > best[0]:
            best = (r, bot, mu + t.max() * a, a)
    return best


def seat(view, crank_axle, rear_axle):
    """Top of the saddle: the component with the highest point behind the crank axle."""
    best, top = None, -np.inf
    for c in view.comps:
        mu, lo, hi, _, _ = view.stats(c)
        if not (rear_axle[0] < mu[0] < crank_axle[0] + 0.05) or abs(mu[2]) > 0.05:
            continue
        if hi[1] > top:
            best, top = c, hi[1]
    if best is None:
        return None
    p = view.pts(best)
    lo, hi = p.min(0), p.max(0)
    xc = 0.5 * (lo[0] + hi[0])
    band = (np.abs(p[:, 0] - xc) < 0.015) & (np.abs(p[:, 2]) < 0.01)
    if band.sum() == 0:
        band = np.abs(p[:, 0] - xc) < 0.03
    if band.sum() == 0:  # a saddle with no vertex near its middle (low-poly): its top
        band = np.ones(len(p), bool)
    return np.array([xc, p[band, 1].max() - SEAT_DEPTH, 0.0])


PEDAL_TWIN_AREA = 0.9     # pieces this close in area to the largest beside it are one pedal's pieces
PEDAL_TWIN_GAP = 0.12     # m between their centres: at most a pedal's length


def pedals(view, crank_axle):
    """Centres of the largest components beyond the crank arms on each side.  Pieces of about
    the largest one's area next to it (a rat-trap pedal's two cages, a pedal of two mirrored
    plates) are that pedal too: which of two equal pieces is 'the largest' is the file's
    rounding, and changes when the model is turned or re-exported."""
    out = {}
    for name, sg in (("pedal_right", 1), ("pedal_left", -1)):
        cands = []
        for c in view.comps:
            mu, lo, hi, _, _ = view.stats(c)
            r = np.hypot(mu[0] - crank_axle[0], mu[1] - crank_axle[1])
            if sg * mu[2] < 0.08 or not (0.06 < r < 0.3):
                continue
            if np.hypot(*(view.pts(c)[:, :2] - crank_axle[:2]).T).max() > 0.35:
                continue
            cands.append((c, mu))
        if cands:
            best, bmu = max(cands, key=lambda cm: cm[0].area)
            p = np.concatenate([view.pts(c) for c, mu in cands if c.area >= PEDAL_TWIN_AREA * best.area
                                and np.linalg.norm(mu - bmu) < PEDAL_TWIN_GAP])
            out[name] = 0.5 * (p.min(0) + p.max(0))
    return out


def handles(view, steer_top, seat_pt):
    """Grip centres (or drop-bar hood positions) on each side."""
    out = {}
    side_comps = {1: [], -1: []}
    bar = None
    for c in view.comps:
        mu, lo, hi, ax, sd = view.stats(c)
        if mu[1] < steer_top[1] - 0.2 or mu[0] < seat_pt[0] + 0.15:
            continue
        if lo[2] < -0.1 and hi[2] > 0.1:   # spans both sides: the bar itself
            if bar is None or c.area > bar.area:
                bar = c
            continue
        for sg in (1, -1):
            if sg * mu[2] > 0.08 and (hi - lo).max() < 0.3:
                side_comps[sg].append((c, mu, lo, hi, ax, sd))
    for name, sg in (("handle_right", 1), ("handle_left", -1)):
        cands = side_comps[sg]
        if not cands:
            continue
        # grips: tubes 1-3 cm thick (brake levers are thinner, hoods are boxes of 8 corners)
        grips = [e for e in cands if e[5][0] > 1.8 * e[5][1] and 0.006 < e[5][2] < 0.03
                 and e[5][0] > 0.02 and len(e[0].verts) >= 24]
        if grips:
            c, mu, lo, hi, ax, sd = max(grips, key=lambda e: e[0].area)
        else:
            c, mu, lo, hi, ax, sd = max(cands, key=lambda e: sg * (e[3][2] if sg > 0 else e[2][2]))
        p = view.pts(c)
        if grips:
            # a grip: half its length back from its outer end, along its end direction (the
            # middle for a straight grip; a bent grip keeps its outer half's direction)
            a = ax[0] if ax[0][2] * sg > 0 else -ax[0]
            t = (p - mu) @ a
            length = t.max() - t.min()
            end = p[t > t.max() - 0.08 * length].mean(0)
            outer = p[t > t.max() - 0.5 * length].mean(0)
            d = end - outer
            d = d / np.linalg.norm(d) if np.linalg.norm(d) > 0 else a
            out[name] = end - 0.5 * length * d
        elif bar is not None:
            # a hood on a drop bar: the bar's centreline next to it (local mean shift)
            bp = view.pts(bar)
            q = 0.5 * (lo + hi)
            for _ in range(20):
                near = np.linalg.norm(bp - q, axis=1) < 0.03
                if near.sum() < 3:
                    break
                q = bp[near].mean(0)
            out[name] = q
        else:
            out[name] = mu
    return out


def estimate(view, pose):
    """{name: canonical (3,)} for the keypoints that could be found, plus notes."""
    kp, notes = {}, []
    fa = pose.apply(pose.front.centre)
    ra = pose.apply(pose.rear.centre)
    fa[2] = ra[2] = 0.0   # on the symmetry plane (a model's wheels may sit a little askew)
    kp["front_axle"], kp["rear_axle"] = fa, ra
    kp["ground"] = np.array([ra[0], 0.0, 0.0])
    if pose.crank is not None:
        ca = pose.apply(pose.crank.centre)
        ca[2] = 0.0
    else:
        ca = np.array([0.0, 0.8 * ra[1], 0.0])
        notes.append("crank_axle: guessed (no chainring found)")
    kp["crank_axle"] = ca
    ht = head_tube(view, fa, ca)
    if ht is not None:
        r, bot, top, a = ht
        kp["steer_bottom"] = bot + HEAD_INSET * a
        kp["steer_top"] = top - HEAD_INSET * a
    else:
        notes.append("steer_top/steer_bottom: no head tube found")
    s = seat(view, ca, ra)
    if s is not None:
        kp["seat"] = s
    else:
        notes.append("seat: no saddle found")
    kp.update(pedals(view, ca))
    if "steer_top" in kp and "seat" in kp:
        kp.update(handles(view, kp["steer_top"], kp["seat"]))
    for n in KEYPOINT_NAMES:
        if n not in kp and not any(x.startswith(n) for x in notes):
            notes.append(f"{n}: not found")
    info = {"head_tube_radius": ht[0] if ht else None}
    return {k: np.asarray(v, float) for k, v in kp.items()}, notes, info

"""The shape-based path of the curation, between the pose and the split (numpy, no bpy):
surface samples of the kept bike, the two-wheeler checks that need the canonical frame, and the
choice between piece-based and shape-based keypoints (a rider's removal: rider_removal.py)."""
import numpy as np

from ..contract import UserError
from . import keypoints as kpmod
from . import shape_keypoints as sk
from .sample_subset import thin
from .silhouette import surface_samples
from .validate import validate


def shape_samples(view, keep_tri, spacing=0.01, max_points=2000000):
    """Surface points of the kept triangles (canonical metres) no further than ~spacing apart.

    All of them up to max_points (the ten development models give 0.17-1.9 M): a subset made the
    shape finders' near-ties (two steering lines, a bar end's place) depend on which points it
    kept; above it, a subset that depends on the shape alone (sample_subset.py)."""
    T = view.soup.TW[keep_tri]
    used = np.unique(T)
    remap = np.full(len(view.P), -1)
    remap[used] = np.arange(len(used))
    return thin(surface_samples(view.P[used], remap[T], spacing), max_points)


def _annulus(X, c, r, lo=0.8, hi=1.0):
    d = np.hypot(X[:, 0] - c[0], X[:, 1] - c[1])
    return X[(d > lo * r) & (d < hi * r)]


def tyre_half_width(X, c, r):
    A = _annulus(X, c, r, 0.88, 1.0)
    A = A[np.abs(A[:, 2] - c[2]) < 0.5 * r]
    return float(np.percentile(np.abs(A[:, 2] - c[2]), 80)) if len(A) else 0.05 * r


def check_two_wheels(X, pose):
    """UserError when a wheel has a twin on the same axle (a tricycle or quad seen from the side
    shows two circles, the twin hides behind its partner)."""
    for name, w in (("rear", pose.rear), ("front", pose.front)):
        c = pose.apply(w.centre)
        r = w.radius * pose.scale
        A = _annulus(X, c, r, 0.8, 1.02)
        if len(A) < 10:
            continue
        # a tyre is one continuous slab across its plane; twins are two slabs with a gap
        # between them (signed: the mid-plane may fall between the twins)
        z = A[:, 2] - c[2]
        zs = np.sort(z)
        gaps = np.nonzero(np.diff(zs) > 0.15 * r)[0]
        if not len(gaps):
            continue
        edges = np.r_[zs[0] - 1, zs[gaps] + 1e-9, zs[-1] + 1]
        full = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            grp = A[(z > lo) & (z <= hi)]
            ang = np.arctan2(grp[:, 1] - c[1], grp[:, 0] - c[0])
            if len(np.unique(((ang + np.pi) / (2 * np.pi) * 36).astype(int) % 36)) >= 27:
                full.append(float(np.median(grp[:, 2] - c[2])))
        if len(full) >= 2:
            raise UserError(f"two wheels side by side on the {name} axle ({abs(full[-1] - full[0]) * 100:.0f} cm "
                            f"apart): a tricycle or quad, not a two-wheeler")


def _recentre(kp, view, X, pose, dx):
    """Move the canonical origin by dx along X (crank axle found after the pose)."""
    pose.M[0, 3] -= dx
    view.P[:, 0] -= dx
    view.tri_c[:, 0] -= dx
    X[:, 0] -= dx
    for k in kp:
        kp[k] = kp[k] - np.array([dx, 0.0, 0.0])


def shape_keypoints(X, pose, auto):
    """Keypoints from the shape alone; (kp, notes, has_crank or None)."""
    kp = {k: auto[k].copy() for k in ("front_axle", "rear_axle", "ground")}
    fa, ra = kp["front_axle"], kp["rear_axle"]
    R = 0.5 * (pose.front.radius + pose.rear.radius) * pose.scale
    notes, has_crank = [], None
    hw = max(tyre_half_width(X, fa, R), tyre_half_width(X, ra, R))
    ped = sk.pedals(X, fa, ra, R, hw)
    if pose.crank is not None:
        kp["crank_axle"] = auto["crank_axle"].copy()
        if "pedal_left" in auto and "pedal_right" in auto:
            kp["pedal_left"], kp["pedal_right"] = auto["pedal_left"], auto["pedal_right"]
        elif ped is not None:
            ca = kp["crank_axle"]
            v = 0.5 * (ped[2][:2] - ped[1][:2])
            kp["pedal_right"] = np.array([ca[0] + v[0], ca[1] + v[1], ped[2][2]])
            kp["pedal_left"] = np.array([ca[0] - v[0], ca[1] - v[1], ped[1][2]])
    elif ped is not None:
        kp["crank_axle"], kp["pedal_left"], kp["pedal_right"], has_crank = ped
        if not has_crank:
            notes.append("no crank: pedals and crank_axle at the footrests (lateral extremes between the wheels)")
    else:
        kp["crank_axle"] = auto["crank_axle"].copy()
        notes.append("crank_axle: guessed, pedals: not found (nothing sticks out sideways between the wheels)")
    steer = sk.steering_axis(X, fa, R)
    if steer is not None:
        kp["steer_bottom"], kp["steer_top"] = steer
    else:
        notes.append("steer_top/steer_bottom: no line of surface from the front hub up to the bars")
    s = sk.seat(X, fa, ra, R)
    if s is not None:
        kp["seat"] = s
    else:
        notes.append("seat: nothing stands above the wheels behind the wheelbase middle")
    if steer is not None:
        h = sk.handles(X, kp["steer_top"], kp["seat"][0] if "seat" in kp else kp["crank_axle"][0], R)
        if h is not None:
            kp["handle_left"], kp["handle_right"] = h
        else:
            notes.append("handle_left/handle_right: nothing wide above the steering axis")
    return kp, notes, has_crank


def choose_keypoints(view, pose, X, clean=False):
    """Piece-based keypoints (exact on clean models) unless the shape-based ones validate
    better, or (on a model whose tyres were not separate pieces, `clean` False) the two
    disagree.  Returns (kp, notes, info, has_crank or None)."""
    auto, notes, info = kpmod.estimate(view, pose)
    hc = pose.crank is not None or ("pedal_left" in auto and "pedal_right" in auto)
    probs_c = validate(auto, hc)
    kp, snotes, has_crank = shape_keypoints(X, pose, auto)
    shifted = dict(kp)
    if pose.crank is None and "crank_axle" in kp:  # validated where the origin will be
        shifted = {k: v - np.array([kp["crank_axle"][0], 0.0, 0.0]) for k, v in kp.items()}
    probs_s = validate(shifted, has_crank if has_crank is not None else True)
    if not probs_c and (probs_s or clean or _agree(auto, kp)):
        return auto, notes, info, None
    if len(probs_s) > len(probs_c):
        return auto, notes, info, None
    if pose.crank is None and "crank_axle" in kp and abs(kp["crank_axle"][0]) > 1e-9:
        _recentre(kp, view, X, pose, float(kp["crank_axle"][0]))
    why = probs_c[0] if probs_c else "they disagree with the shape"
    # shape-based steer_top marks the stem top: the head tube is its lower 15 cm (scaled)
    R = 0.5 * (pose.front.radius + pose.rear.radius) * pose.scale
    return kp, [f"keypoints from the shape (piece-based ones: {why})"] + snotes, \
        {"head_tube_radius": None, "head_span": sk.head_zone(X, kp["steer_bottom"], kp["steer_top"], R)
         if "steer_top" in kp and "steer_bottom" in kp else 0.15 * R / 0.35}, has_crank


def _agree(a, b, tol=0.1):
    """Piece-based and shape-based keypoints tell the same story: the same saddle and bar ends
    (within tol metres, 1.5 tol) and the same steering line (the piece finders can latch onto
    the wrong piece; the shape finder puts steer_top higher, at the stem)."""
    for k, t in (("seat", tol), ("handle_right", 1.5 * tol)):
        if k in a and k in b and np.linalg.norm(a[k] - b[k]) > t:
            return False
    if all(k in a and k in b for k in ("steer_top", "steer_bottom")):
        ua = (a["steer_top"] - a["steer_bottom"]) / np.linalg.norm(a["steer_top"] - a["steer_bottom"])
        ub = (b["steer_top"] - b["steer_bottom"]) / np.linalg.norm(b["steer_top"] - b["steer_bottom"])
        d = a["steer_bottom"] - b["steer_bottom"]
        if ua @ ub < np.cos(np.radians(8)) or np.linalg.norm(d - (d @ ub) * ub) > 0.5 * tol:
            return False
    return True

"""Curation's own check that each keypoint lies on its part (numpy, no bpy).

The rig turns the steering about steer_bottom-steer_top, the crank about crank_axle, and the
pedals and grips are where a rider's feet and hands go: a keypoint a few centimetres off its part
(handles beyond the grips, pedals beside the pedal bodies, the crank axle away from the bottom
bracket, steer_top beside the head tube) makes a bike that looks right and poses wrong.  So,
after the split, every keypoint is measured against the surface of the part it belongs to, in
the canonical frame:

- points on a surface (a grip's centre, a pedal body's centre, the saddle top): the 3D distance to
  the part's surface, which is within a tube's or a pedal's half thickness (< 3 cm) when right;
- points on an axis (steer_top and steer_bottom on the head tube / stem, crank_axle in the bottom
  bracket): the distance in the side view (the renders' main view; the axis lies inside a tube
  whose outline covers it) to the part's silhouette;
- the axles are the fitted tyre circles' centres and `ground` is on the ground: not measured.

A distance over 3 cm is a problem naming the keypoint and the distance."""
import numpy as np

from . import split
from .sample_subset import thin
from .silhouette import surface_samples

TOL = 0.03   # metres

# keypoint: (parts whose surface it belongs on, "surface" | "axis")
RULES = {
    "seat": ((split.FRAME,), "surface"),
    "handle_left": ((split.STEERING,), "surface"),
    "handle_right": ((split.STEERING,), "surface"),
    "pedal_left": ((split.CRANK,), "surface"),
    "pedal_right": ((split.CRANK,), "surface"),
    "crank_axle": ((split.CRANK, split.FRAME), "axis"),
    "steer_top": ((split.STEERING, split.FRAME), "axis"),
    "steer_bottom": ((split.STEERING, split.FRAME), "axis"),
}


def part_samples(P, TW, tri_mask, spacing=0.01, max_points=150000):
    """Surface points (canonical metres) of the triangles in tri_mask, ~spacing apart."""
    T = TW[tri_mask]
    if len(T) == 0:
        return np.zeros((0, 3))
    used = np.unique(T)
    remap = np.full(len(P), -1)
    remap[used] = np.arange(len(used))
    return thin(surface_samples(P[used], remap[T], spacing), max_points)


def distances(P, TW, labels, kp, has_crank):
    """{keypoint: (metres from its part (3D for surface points, side view for axis points),
    the parts)}."""
    out = {}
    cache = {}
    for name, (parts, kind) in RULES.items():
        if name not in kp:
            continue
        if not has_crank and name.startswith("pedal"):
            parts = (split.FRAME,)   # footrests, a deck: the frame carries them
        key = tuple(parts)
        if key not in cache:
            cache[key] = part_samples(P, TW, np.isin(labels, parts))
        S = cache[key]
        if len(S) == 0:
            out[name] = (float("inf"), parts)
            continue
        d = S - np.asarray(kp[name], float)
        out[name] = (float(np.sqrt((d ** 2).sum(1).min() if kind == "surface" else (d[:, :2] ** 2).sum(1).min())),
                     parts)
    return out


SNAP_MAX = 0.12   # metres: further than this from its part, a keypoint is wrong, not a little off


def snap(P, TW, labels, kp, has_crank, tol=TOL):
    """Grips and pedals a little off their part (handles placed beyond the grips' ends, pedals
    beside the pedal bodies: 3-12 cm) moved onto it: to the middle of the part's surface within
    `tol` of its nearest point, then made a mirror pair again (grips) or opposite about
    crank_axle again (pedals: arms modelled at an angle, pedals as separate pieces).  Returns
    the names moved; the keypoints are changed in place."""
    moved = []
    for names, parts in ((("handle_left", "handle_right"), (split.STEERING,)),
                         (("pedal_left", "pedal_right"), (split.CRANK,) if has_crank else (split.FRAME,))):
        if not all(n in kp for n in names):
            continue
        S = part_samples(P, TW, np.isin(labels, parts))
        if len(S) == 0:
            continue
        new = {}
        for n in names:
            q = np.asarray(kp[n], float)
            d = np.linalg.norm(S - q, axis=1)
            if tol < d.min() <= SNAP_MAX:
                near = S[np.linalg.norm(S - S[np.argmin(d)], axis=1) <= tol]
                new[n] = near.mean(0)
        far = [n for n in names if np.linalg.norm(S - np.asarray(kp[n], float), axis=1).min() > SNAP_MAX]
        if len(far) == 1 and (names[0] == "handle_left" or "crank_axle" in kp):
            # one of the pair far from everything (a footpeg lost in an exhaust, a grip found on
            # a mirror): the other one's mirror image, when that lands on the part
            good = [n for n in names if n not in far][0]
            g = new.get(good, np.asarray(kp[good], float))
            if names[0] == "handle_left":
                m = g * [1, 1, -1]
            else:
                c = np.asarray(kp["crank_axle"], float)
                m = np.array([2 * c[0] - g[0], 2 * c[1] - g[1], -g[2]])
            if np.linalg.norm(S - m, axis=1).min() <= tol:
                new[far[0]] = m
        if not has_crank and names[0] == "pedal_left":
            # footrests (no crank): one still off the frame (the finder's lateral extreme was a
            # side stand or a silencer) goes to the frame's outermost surface beside the other's
            # height and place, on its own side
            for n in names:
                q = new.get(n, np.asarray(kp[n], float))
                if np.linalg.norm(S - q, axis=1).min() <= tol:
                    continue
                side = S[(np.hypot(S[:, 0] - q[0], S[:, 1] - q[1]) < 0.06) & (np.sign(S[:, 2]) == np.sign(q[2]))]
                if len(side):
                    new[n] = side[np.argmax(np.abs(side[:, 2]))]
            if new:
                for n, v in new.items():
                    kp[n] = v
                moved += list(new)
            continue
        if not new:
            continue
        a, b = (new.get(n, np.asarray(kp[n], float)) for n in names)
        if names[0] == "handle_left":
            def mirror(p):
                return p * [1, 1, -1]
            xy, w = 0.5 * (a[:2] + b[:2]), 0.5 * (b[2] - a[2])
            pairs = [(np.array([xy[0], xy[1], -w]), np.array([xy[0], xy[1], w]))]
        elif "crank_axle" in kp:
            c = np.asarray(kp["crank_axle"], float)

            def mirror(p):
                return np.array([2 * c[0] - p[0], 2 * c[1] - p[1], -p[2]])
            v = 0.5 * ((b[:2] - c[:2]) - (a[:2] - c[:2]))
            pairs = [(np.array([c[0] - v[0], c[1] - v[1], a[2]]), np.array([c[0] + v[0], c[1] + v[1], b[2]]))]
        else:
            pairs = []
        if pairs:
            # the averaged pair, or either one with its mirror image: whichever lies closest
            pairs += [(a, mirror(a)), (mirror(b), b)]
            a, b = min(pairs, key=lambda pq: max(np.linalg.norm(S - pq[0], axis=1).min(),
                                                 np.linalg.norm(S - pq[1], axis=1).min()))
        kp[names[0]], kp[names[1]] = a, b
        moved += list(new)
    return moved


def pedal_pieces(soup, P, labels, kp, keep_tri, tol=TOL, size=0.25):
    """Pedal bodies modelled as their own pieces go with the crank: each mesh piece (kept, at
    most `size` metres across) whose surface comes within `tol` of a pedal keypoint.  The
    region split labels a piece by where it lies, and a pedal at the end of an arm modelled at
    an angle lies outside the crank's disc.  Changes labels in place; returns how many."""
    n = 0
    for name in ("pedal_left", "pedal_right"):
        q = np.asarray(kp[name], float)
        for c in soup.comps:
            pts = P[c.verts]
            if np.ptp(pts, axis=0).max() > size or not keep_tri[c.tris].all():
                continue
            if np.any(pts.min(0) - tol > q) or np.any(pts.max(0) + tol < q):
                continue
            T = soup.TW[c.tris]
            S = part_samples(P, T, np.ones(len(T), bool), spacing=0.005)
            if len(S) and np.linalg.norm(S - q, axis=1).min() <= tol and (labels[c.tris] != split.CRANK).any():
                labels[c.tris] = split.CRANK
                n += 1
    return n


def check(P, TW, labels, kp, has_crank, tol=TOL):
    """(problems, distances): one problem per keypoint further than tol from its part."""
    dist = distances(P, TW, labels, kp, has_crank)
    probs = []
    for name, (d, parts) in dist.items():
        if d > tol:
            part = "/".join(split.PART_NAMES[p] for p in parts)
            how = "in the side view " if RULES[name][1] == "axis" else ""
            probs.append(f"{name}: {d * 100:.1f} cm {how}from the {part} surface (keypoints lie on their part "
                         f"within {tol * 100:.0f} cm)")
    return probs, {k: v[0] for k, v in dist.items()}

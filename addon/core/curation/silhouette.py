"""Wheels from the side-view silhouette (numpy, no bpy).

Real models do not give us one clean mesh piece per tyre: tyres have 10-33 segments, are fat
(scooters, motorcycles), fused to the rim and frame, or the whole bike is one mesh.  What every
two-wheeler does have is a side view in which the two tyres are the two big circles of the
outline.  So:

1. lateral axis: the thinnest principal axis of the surface (the other two are tried when the
   thinnest gives no wheels: a scooter with a tall stem, a rider with spread arms);
2. the surface is sampled densely and rasterised onto the side plane as an occupancy image;
3. a Hough-style circle search on the outline: every outline pixel votes, along its inward
   normal (towards the occupied side), for centres at each radius; only the outer boundary of
   a filled disc or annulus votes for its own centre, so rims, holes and hubs do not compete
   with the tyre's outer circle;
4. circle candidates are scored by the share of their circumference that is outline;
5. the two wheels are the best-supported pair of similar, disjoint circles side by side.
Positions are then refined on the mesh's own vertices (outline points per angular sector,
least-squares circle, plane through both tyres' outer bands), so pixel size does not limit
the accuracy.
"""
from dataclasses import dataclass, field

import numpy as np

from ..contract import UserError
from .wheels import fit_circle_2d

IMAGE_PX = 200          # pixels along the longer side of the side view
MIN_SUPPORT = 0.5       # share of a wheel's circumference that must be (outward-facing) outline
MIN_PAIR_SUPPORT = 1.2  # and both wheels together (one tyre may be half hidden by a rider's leg)
GROUND_MIN_SUPPORT = 0.35   # each wheel of a pair standing on a common ground line
GROUND_PAIR_SUPPORT = 0.9   # and both together
GROUND_BONUS = 4.0          # a pair standing on the ground ranks above any pair that does not


@dataclass
class Circle:
    centre: np.ndarray   # (2,) side-plane coordinates (model units)
    radius: float
    support: float       # share of the circumference found on the outline


@dataclass
class SideView:
    normal: np.ndarray           # (3,) lateral unit axis
    e1: np.ndarray               # (3,) in-plane axes
    e2: np.ndarray
    origin: np.ndarray           # (3,)
    circles: list = field(default_factory=list)   # Circle, best first
    thickness: float = 0.0       # lateral extent / in-plane extent (flat icon check)


def surface_samples(P, TW, spacing):
    """Points on the triangles no further than ~spacing apart (vertices, edges and interiors),
    so a large face (a disc wheel's side, a low-poly tyre) fills the image, not just its corners."""
    tri = P[TW]
    # zero-area triangles (slivers that only link pieces) are no surface
    tri = tri[np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) > 0]
    e = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]], 1)
    longest = np.linalg.norm(e, axis=2).max(1)
    k = np.clip(np.ceil(longest / spacing), 1, 512).astype(int)
    out = [P]
    for kk in np.unique(k):
        sel = tri[k == kk]
        i, j = np.meshgrid(np.arange(kk + 1), np.arange(kk + 1), indexing="ij")
        m = i + j <= kk
        b = np.stack([i[m], j[m], kk - i[m] - j[m]], 1) / kk   # barycentric grid
        out.append(np.einsum("bk,tkd->tbd", b, sel).reshape(-1, 3))
    return np.concatenate(out)


def principal_axes(X):
    mu = X.mean(0)
    w, v = np.linalg.eigh(np.cov((X - mu).T))
    return mu, v.T, np.sqrt(np.maximum(w, 0))   # ascending spread


def _blur(img, passes=2):
    out = img.astype(float)
    for _ in range(passes):   # [1 2 1]/4 separable, ~ Gaussian sigma 0.7 px per pass
        out = np.pad(out, 1, mode="edge")
        out = (out[:-2] + 2 * out[1:-1] + out[2:]) / 4
        out = (out[:, :-2] + 2 * out[:, 1:-1] + out[:, 2:]) / 4
    return out


def occupancy(uv, lo, px, shape):
    img = np.zeros(shape, bool)
    ij = np.floor((uv - lo) / px).astype(int)
    ok = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < shape[1]) & (ij[:, 1] < shape[0])
    img[ij[ok, 1], ij[ok, 0]] = True
    # close one-pixel gaps between samples
    pad = np.pad(img, 1)
    grown = pad[1:-1, 1:-1] | pad[:-2, 1:-1] | pad[2:, 1:-1] | pad[1:-1, :-2] | pad[1:-1, 2:]
    return grown


def hough_circles(img, rmin, rmax, max_circles=8):
    """Circle candidates (x, y, r in pixels, support) of an occupancy image's outline."""
    pad = np.pad(img, 1)
    edge = img & ~(pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:])
    b = _blur(img, 3)
    gy, gx = np.gradient(b)
    ys, xs = np.nonzero(edge)
    g = np.stack([gx[ys, xs], gy[ys, xs]], 1)
    n = np.linalg.norm(g, axis=1)
    ok = n > 1e-6
    ys, xs, g = ys[ok], xs[ok], g[ok] / n[ok, None]   # unit inward normal (towards occupied)
    H, W = img.shape
    radii = np.arange(rmin, rmax + 1)
    # votes in a +-12 degree cone around the inward normal: tolerant of polygonal tyres
    acc = np.zeros((len(radii), H, W), np.float32)
    for da in np.radians([-12, -6, 0, 6, 12]):
        c, s = np.cos(da), np.sin(da)
        d = np.stack([c * g[:, 0] - s * g[:, 1], s * g[:, 0] + c * g[:, 1]], 1)
        cx = np.rint(xs[None, :] + radii[:, None] * d[None, :, 0]).astype(int)
        cy = np.rint(ys[None, :] + radii[:, None] * d[None, :, 1]).astype(int)
        ri = np.broadcast_to(np.arange(len(radii))[:, None], cx.shape)
        m = (cx >= 0) & (cy >= 0) & (cx < W) & (cy < H)
        np.add.at(acc, (ri[m], cy[m], cx[m]), 1.0)
    # smooth over position (3x3) and radius (+-1): polygons and pixels smear the peak
    acc = acc[:, :-2] + acc[:, 1:-1] + acc[:, 2:]
    acc = np.pad(acc, ((0, 0), (1, 1), (0, 0)))
    acc = acc[:, :, :-2] + acc[:, :, 1:-1] + acc[:, :, 2:]
    acc = np.pad(acc, ((0, 0), (0, 0), (1, 1)))
    acc = acc[:-2] + acc[1:-1] + acc[2:]
    acc = np.pad(acc, ((1, 1), (0, 0), (0, 0)))
    score = acc / (2 * np.pi * radii[:, None, None] * 5)
    # candidates per radius band (log-spaced): small circles (spoke gaps, bolts) are many and
    # would crowd out the few big ones if ranked together
    out = []
    edges = np.unique(np.geomspace(rmin, rmax + 1, 7).astype(int))
    for lo_r, hi_r in zip(edges[:-1], edges[1:]):
        band = score[(radii >= lo_r) & (radii < hi_r)]
        base = int(np.searchsorted(radii, lo_r))
        got = []
        for f in np.argsort(band.ravel())[::-1][:5000]:
            ri, y, x = np.unravel_index(f, band.shape)
            r = float(radii[base + ri])
            if any(np.hypot(x - o[0], y - o[1]) < 0.5 * max(r, o[2]) for o in got):
                continue
            got.append((float(x), float(y), r, circle_support(edge, x, y, r, img=img)))
            if len(got) >= max_circles:
                break
        out += got
    return sorted(out, key=lambda o: -o[3] * o[2])


def circle_support(edge, x, y, r, n=90, img=None):
    """Share of n directions around (x, y) with an outline pixel at distance r (+-4 %).  With
    the occupancy image, an outline pixel counts only where the outside beyond it is empty: a
    tyre's outline faces outwards, a circle inscribed between frame tubes touches their inner
    edges with tube beyond."""
    H, W = edge.shape
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    tol = max(1.5, 0.04 * r)
    hit = np.zeros(n, bool)
    for dr in np.arange(-tol, tol + 0.5, 0.5):
        px = np.rint(x + (r + dr) * np.cos(a)).astype(int)
        py = np.rint(y + (r + dr) * np.sin(a)).astype(int)
        ok = (px >= 0) & (py >= 0) & (px < W) & (py < H)
        h = np.zeros(n, bool)
        h[ok] = edge[py[ok], px[ok]]
        hit |= h
    if img is not None:
        ro = r + tol + 1.5
        px = np.rint(x + ro * np.cos(a)).astype(int)
        py = np.rint(y + ro * np.sin(a)).astype(int)
        ok = (px >= 0) & (py >= 0) & (px < W) & (py < H)
        empty = np.ones(n, bool)
        empty[ok] = ~img[py[ok], px[ok]]
        hit &= empty
    return float(hit.mean())


def side_view(P, TW, normal, px_count=IMAGE_PX):
    """Circles in the projection of the mesh along `normal`."""
    normal = normal / np.linalg.norm(normal)
    e1 = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    mu = P.mean(0)
    Q = P - mu
    uv = np.stack([Q @ e1, Q @ e2], 1)
    lo, hi = uv.min(0), uv.max(0)
    ext = float((hi - lo).max())
    if ext <= 0:
        return SideView(normal, e1, e2, mu, [], 0.0)
    px = ext / px_count
    S = surface_samples(P, TW, 0.5 * px)
    suv = np.stack([(S - mu) @ e1, (S - mu) @ e2], 1)
    lo = lo - 3 * px
    shape = (int(np.ceil((hi[1] - lo[1]) / px)) + 4, int(np.ceil((hi[0] - lo[0]) / px)) + 4)
    img = occupancy(suv, lo, px, shape)
    lat = Q @ normal
    sv = SideView(normal, e1, e2, mu, [], float((lat.max() - lat.min()) / ext))
    rmin, rmax = max(5, int(0.04 * px_count)), int(0.45 * px_count)
    for x, y, r, sup in hough_circles(img, rmin, rmax):
        c = lo + (np.array([x, y]) + 0.5) * px
        sv.circles.append(Circle(c, r * px, sup))
    sv.image, sv.lo, sv.px = img, lo, px
    return sv


def merge_concentric(circles):
    """One circle per wheel: candidates around the same centre with similar radii (a tyre seen in
    two radius bands, its tyre and rim outlines, a mudguard arc over it) become the best-supported
    of them.  Without this, a clean spoked bicycle showed "4 round outlines" and no pair."""
    out = []
    for c in sorted(circles, key=lambda c: -c.support * c.radius):
        if any(np.linalg.norm(c.centre - o.centre) < 0.25 * max(c.radius, o.radius)
               and min(c.radius, o.radius) > 0.75 * max(c.radius, o.radius) for o in out):
            continue
        out.append(c)
    return out


def ground_line(sv, a, b):
    """The line tangent to both circles from the side that nothing of the vehicle crosses: the
    ground both wheels stand on.  (unit outward normal n, offset g: the ground is n.x = g), or
    None when both common tangents cut through the side view (the circles are not the two
    wheels the vehicle stands on: a basket, a headlight, a chainring, a covered scooter's
    front)."""
    if getattr(sv, "image", None) is None:
        return None
    d = b.centre - a.centre
    L = float(np.linalg.norm(d))
    if L <= 0:
        return None
    u = d / L
    p = np.array([-u[1], u[0]])
    s = (a.radius - b.radius) / L
    if abs(s) >= 1:
        return None
    c = np.sqrt(1 - s * s)
    ys, xs = np.nonzero(sv.image)
    pts = sv.lo + (np.stack([xs, ys], 1) + 0.5) * sv.px
    R = 0.5 * (a.radius + b.radius)
    tol = 2.5 * sv.px + 0.03 * R
    best = None
    for sg in (1, -1):
        n = s * u + sg * c * p
        g = float(n @ a.centre + a.radius)
        beyond = int(((pts @ n) - g > tol).sum())
        if beyond <= max(3, 0.003 * len(pts)) and (best is None or beyond < best[2]):
            best = (n, g, beyond)
    return None if best is None else best[:2]


def on_ground(circ, ground, R):
    """Whether a circle's bottom reaches the ground line (a wheel, not a lamp or basket)."""
    n, g = ground
    return float(n @ circ.centre + circ.radius) >= g - 0.1 * R


def pairs(circles, min_support=MIN_SUPPORT, sv=None, grounded_ok=True):
    """(score, a, b) of disjoint circle pairs, best first (any size ratio: checks come later).

    The wheels are the two circles the vehicle stands on: both tangent to one line that nothing
    of the side view crosses (the ground), one behind the other along it.  Such a pair ranks
    above any other and needs less outline (a covered scooter's body hides the top of its small
    wheels; a rider's legs or mudguards hide parts of a tyre): each >= 35 %, together >= 90 %.
    A third round outline (a basket, a headlight, a chainring, a mudguard arc, a scooter's front)
    stands on nothing, so it cannot pair with a wheel.  Without the side view image (or when no
    pair stands on a common ground: a display base under the wheels) the best-supported pair.
    grounded_ok False (a view along a thicker axis than the thinnest, where a front or top
    view's round ends can stand on a line too): only well-supported pairs, as before."""
    circles = merge_concentric(circles)
    out = []
    for i, a in enumerate(circles):
        for b in circles[i + 1:]:
            if min(a.support, b.support) < GROUND_MIN_SUPPORT:
                continue
            d = np.linalg.norm(a.centre - b.centre)
            if d < 0.95 * (a.radius + b.radius):
                continue
            ratio = min(a.radius, b.radius) / max(a.radius, b.radius)
            # big, well-supported, and similar: a wheel pair beats a wheel and a headlight
            score = (a.support + b.support) * (a.radius + b.radius) * ratio
            strong = min(a.support, b.support) >= min_support and a.support + b.support >= MIN_PAIR_SUPPORT
            grounded = grounded_ok and a.support + b.support >= GROUND_PAIR_SUPPORT \
                and ground_line(sv, a, b) is not None
            if grounded:
                out.append((GROUND_BONUS * score, a, b))
            elif strong:
                out.append((score, a, b))
    out.sort(key=lambda t: -t[0])
    return out


def refine(P, sv, circ, sectors=72, spread=0.15):
    """Circle fit on the mesh's vertices: the outermost vertex per angular sector within
    [0.8 r, 1.12 r] of the Hough circle, outliers (fenders, a fork) dropped by residual."""
    Q = P - sv.origin
    uv = np.stack([Q @ sv.e1, Q @ sv.e2], 1)
    c, r = circ.centre, circ.radius
    r_found = r
    for _ in range(3):
        d = uv - c
        rho = np.hypot(d[:, 0], d[:, 1])
        m = (rho > 0.8 * r) & (rho < 1.12 * r)
        if m.sum() < 6:
            return c, r, np.zeros(0, int)
        idx = np.nonzero(m)[0]
        sec = ((np.arctan2(d[idx, 1], d[idx, 0]) + np.pi) / (2 * np.pi) * sectors).astype(int) % sectors
        order = np.lexsort((rho[idx], sec))
        last = np.r_[sec[order][1:] != sec[order][:-1], True]
        outer = idx[order][last]
        if len(outer) < 6:
            return c, r, idx
        cc, rr = _ransac_circle(uv[outer], r_found, spread=spread)
        c, r = cc, rr
    # the tyre's band around its outer radius: symmetric about the wheel's mid-plane for thin
    # and fat tyres alike (the outline vertices alone sit on one shoulder of a fat tyre)
    d = uv - c
    rho = np.hypot(d[:, 0], d[:, 1])
    return c, r, np.nonzero((rho > 0.9 * r) & (rho < 1.01 * r))[0]


def outlines_alike(ra, rb):
    """Two side-view circles the outline shows as the same size: radii within 5 %.  The
    outline's radii are whole pixels (38 and 40 px are exactly 5 % apart), and the pixel size's
    last bit follows the order the file lists its triangles in (the side view's axes are summed
    over the surface samples): a tie is a difference, whatever the rounding (the robot bike's
    wheels were refitted or not by its OBJ's and its glTF re-export's triangle order)."""
    return abs(ra - rb) < 0.05 * (1 - 1e-9) * max(ra, rb)


def _ransac_circle(xy, r0, tries=300, spread=0.15):
    """Least-squares circle on the inliers of the best 3-point circle: the outline points of a
    tyre, without the stays, fork legs and mudguard stays that cross the band around it."""
    rng = np.random.default_rng(0)
    tol = 0.006 * r0
    best, best_n = None, -10 ** 9
    n = len(xy)
    for _ in range(tries):
        i = rng.choice(n, 3, replace=False)
        try:
            c, r = fit_circle_2d(xy[i])
        except np.linalg.LinAlgError:
            continue
        if not ((1 - spread) * r0 < r < (1 + spread) * r0):
            continue
        res = np.hypot(*(xy - c).T) - r
        inl = np.abs(res) < tol
        # the tyre is the outer outline: a candidate with points outside it nearly all the way
        # round (6 of 8 octants) is a rim or the spoke ends inside its tyre, however few the
        # tyre's corners (a mudguard, a chainring or a pedal next to a tyre lies outside on one
        # side only, however many points it has)
        out = res > 0.02 * r0
        if len(np.unique(np.floor(np.arctan2(*(xy[out] - c)[:, ::-1].T) / (np.pi / 4)))) >= 6:
            continue
        score = int(inl.sum())
        if score > best_n:
            best, best_n = inl, score
    if best is None or best.sum() < 4:
        return fit_circle_2d(xy)
    c, r = fit_circle_2d(xy[best])
    inl = np.abs(np.hypot(*(xy - c).T) - r) < tol
    return fit_circle_2d(xy[inl]) if inl.sum() >= 4 else (c, r)


def find_side_view(P, TW):
    """The side view with the best wheel pair (thinnest axis first, then the others)."""
    S = surface_samples(P, TW, 0.02 * float(np.linalg.norm(P.max(0) - P.min(0))))
    _, axes, spread = principal_axes(S)
    if spread[2] <= 0:
        raise UserError("the model has no extent (all vertices at one point)")
    tried = []
    for k in range(3):
        sv = side_view(P, TW, axes[k])
        pr = pairs(sv.circles, sv=sv, grounded_ok=k == 0)
        tried.append((pr[0][0] if pr else 0.0, k, sv, pr))
        # the thinnest axis giving two well-supported similar circles, or two it stands on, is
        # the lateral one (a top or front view has round ends that can look grounded too)
        if k == 0 and pr and min(pr[0][1].radius, pr[0][2].radius) > 0.6 * max(pr[0][1].radius, pr[0][2].radius) \
                and (min(pr[0][1].support, pr[0][2].support) > 0.6 or ground_line(sv, pr[0][1], pr[0][2]) is not None):
            break
    best = max(tried, key=lambda t: t[0])
    return best[2], best[3], spread


def _frame(normal):
    normal = normal / np.linalg.norm(normal)
    e1 = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    return normal, e1, np.cross(normal, e1)


def wheel_rings(soup, skip=None):
    """The two wheels as wheels.Ring (comp = -1) from the side view, refined on the vertices,
    plus (side view, all circles, band vertex indices per wheel).  skip: bool per soup component
    left out of the search (backdrops).  UserError naming the failed check for models that are
    not two-wheelers."""
    from .wheels import Ring
    P, TW = soup.P, soup.TW
    used = None
    if skip is not None and skip.any() and not skip.all():
        # the search sees the vehicle only: a ground plane under it would be the thinnest
        # direction of the whole and fill the side view (a leaning motorcycle on a 12 m sheet)
        keep_t = ~soup.tri_mask(skip)
        used = np.unique(TW[keep_t])
        remap = np.full(len(P), -1)
        remap[used] = np.arange(len(used))
        P, TW = P[used], remap[TW[keep_t]]
    sv, pr, spread = find_side_view(P, TW)
    if sv.thickness < 0.03:
        raise UserError(f"not a 3D two-wheeler: the model is flat (thickness {sv.thickness * 100:.1f} % of its "
                        f"length; a flat icon or a single sheet)")
    if not pr:
        n = sum(c.support >= MIN_SUPPORT for c in sv.circles)
        raise UserError(f"no wheels found: the side view shows {n} round outline(s), need two disjoint "
                        f"circles (tyres) side by side")
    _, a, b = pr[0]
    ratio = min(a.radius, b.radius) / max(a.radius, b.radius)
    if ratio < 0.6:
        raise UserError(f"wheel sizes very unequal (smaller/larger = {ratio:.2f} < 0.6): a penny-farthing "
                        f"or not a two-wheeler")
    R = 0.5 * (a.radius + b.radius)
    ground = ground_line(sv, a, b)
    # a third wheel stands on the same ground (a trailer, an in-line trike); a round basket,
    # lamp or a covered scooter's front above it is no wheel
    third = [c for c in merge_concentric(sv.circles) if c.support >= 0.6 and c is not a and c is not b
             and min(c.radius, R) > 0.75 * max(c.radius, R)
             and all(np.linalg.norm(c.centre - w.centre) > 0.95 * (c.radius + w.radius) for w in (a, b))
             and (ground is None or on_ground(c, ground, R))]
    if third:
        raise UserError(f"three wheels in the side view ({len(third) + 2} wheel-sized circles): a tricycle "
                        f"or a vehicle with a trailer, not a two-wheeler")
    # refine: circles on the vertices, then the plane through both tyres' outer bands
    cents = [sv.origin + c.centre[0] * sv.e1 + c.centre[1] * sv.e2 for c in (a, b)]
    radii = [a.radius, b.radius]
    normal = sv.normal
    for _ in range(2):
        n, e1, e2 = _frame(normal)
        frame = SideView(n, e1, e2, sv.origin)
        fits = []
        for c3, r in zip(cents, radii):
            c2 = np.array([(c3 - sv.origin) @ e1, (c3 - sv.origin) @ e2])
            fits.append(refine(P, frame, Circle(c2, r, 1.0)))
        # wheels the outline shows equal stay equal: the better-seen tyre sets the size of one
        # half hidden (a rider's foot against it pulls its fit outwards)
        if outlines_alike(a.radius, b.radius) and \
                abs(fits[0][1] - fits[1][1]) > 0.05 * max(fits[0][1], fits[1][1]):
            good, bad = (0, 1) if a.support >= b.support else (1, 0)
            c3 = cents[bad]
            c2 = np.array([(c3 - sv.origin) @ e1, (c3 - sv.origin) @ e2])
            fits[bad] = refine(P, frame, Circle(c2, fits[good][1], 1.0), spread=0.03)
        bands = [f[2] for f in fits]
        # the plane through both tyres' outlines, or one tyre's own (a tricycle's twin wheels
        # seen slightly askew make one outline thick): the one square to the wheelbase and flat
        base = cents[1] - cents[0]
        base = base / np.linalg.norm(base)
        planes = []
        for band in (np.concatenate(bands), bands[0], bands[1]):
            if len(band) >= 6:
                _, ax, sd = principal_axes(P[band])
                # without what crosses the band beside the tyre (a chainring next to a low-poly
                # tyre's few corners tilts the plane by a degree): keep what lies within twice
                # the tyre's own half width (80th percentile) of the plane
                off = (P[band] - P[band].mean(0)) @ ax[0]
                dev = np.abs(off - np.median(off))
                keep = dev <= 2 * np.percentile(dev, 80) + 1e-12
                if 6 <= keep.sum() < len(band):
                    _, ax, sd = principal_axes(P[band][keep])
                nn = ax[0] if ax[0] @ normal > 0 else -ax[0]
                planes.append((abs(nn @ base) + sd[0] / max(sd[2], 1e-12), nn))
        if planes:
            normal = min(planes, key=lambda t: t[0])[1]
        cents = [sv.origin + f[0][0] * e1 + f[0][1] * e2 for f in fits]
        radii = [f[1] for f in fits]
    rings = []
    for c3, r, band in zip(cents, radii, bands):
        lat = float(np.median((P[band] - c3) @ normal)) if len(band) else 0.0
        rings.append(Ring(-1, c3 + lat * normal, normal.copy(), float(r), 0.0))
    if used is not None:
        bands = [used[b] for b in bands]
    return rings, sv, bands


def rings_from_centres(soup, front, rear):
    """The two wheels around centres an annotator placed (model coordinates): lateral axis =
    the thinnest principal axis made perpendicular to the wheelbase, radius = the circle around
    each centre with the most outline (any support: the annotator has the last word)."""
    from .wheels import Ring
    P, TW = soup.P, soup.TW
    front, rear = np.asarray(front, float), np.asarray(rear, float)
    base = front - rear
    L = float(np.linalg.norm(base))
    if L <= 0:
        raise UserError("the two wheel centres are at the same place: drag kp.front_axle and kp.rear_axle apart")
    S = surface_samples(P, TW, 0.02 * float(np.linalg.norm(P.max(0) - P.min(0))))
    _, axes, _ = principal_axes(S)
    d = base / L
    cand = [a - (a @ d) * d for a in axes]
    n = max(cand[:2], key=np.linalg.norm) if np.linalg.norm(cand[0]) < 0.5 else cand[0]
    n = n / np.linalg.norm(n)
    sv = side_view(P, TW, n)
    out, bands = [], []
    pad = np.pad(sv.image, 1)
    edge = sv.image & ~(pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:])
    for c3 in (front, rear):
        c2 = np.array([(c3 - sv.origin) @ sv.e1, (c3 - sv.origin) @ sv.e2])
        x, y = (c2 - sv.lo) / sv.px - 0.5
        rs = np.arange(max(3, int(0.1 * L / sv.px)), int(0.7 * L / sv.px) + 1)
        if len(rs) == 0:
            raise UserError("the wheel centres are too close for wheels to fit between them")
        sup = np.array([circle_support(edge, x, y, r, img=sv.image) for r in rs])
        # the outermost well-supported circle: the tyre, not the rim or hub inside it
        r = float(rs[np.nonzero(sup >= 0.8 * sup.max())[0].max()]) * sv.px
        c2f, rf, band = refine(P, sv, Circle(c2, r, 1.0))
        if abs(rf - r) > 0.2 * r or np.linalg.norm(c2f - c2) > 0.2 * r:   # refinement wandered off
            c2f, rf = c2, r
        lat = float(np.median((P[band] - c3) @ n)) if len(band) else 0.0
        cen = sv.origin + c2f[0] * sv.e1 + c2f[1] * sv.e2 + ((c3 - sv.origin) @ n + lat) * n
        out.append(Ring(-1, cen, n.copy(), float(rf), 0.0))
        bands.append(band)
    return out, bands

"""Keypoints from the bike's shape alone (numpy, no bpy): no assumption about how the model is
cut into pieces, so they work on a single fused mesh, one-piece handlebars, head tubes merged
with the fork, chainrings hidden in chain guards.

Input: surface samples X (n, 3) of the kept bike in the canonical frame (metres) and the wheel
axles.  Lengths are relative to the wheel radius R where a bike's proportions say so (a scooter
scaled to 0.7 m wheels is as big as a house; its bar still sits above its front axle).
- steering axis: the line through (a few cm from) the front hub, leaning back 50-88 degrees,
  that the most surface lies along above the front tyre (fork legs, head tube, steerer, stem);
  steer_bottom just above the tyre, steer_top at the top of that run (the stem);
- handles: the lateral extremes of the bar region (high, ahead of the saddle), the grip centre
  a quarter wheel radius in from the end, mirrored into a symmetric pair;
- pedals: the lateral extremes low between the wheels; when they sit apart in the side view
  (a crank), crank_axle is their midpoint; when they coincide (footpegs, a deck) there is no
  crank and crank_axle is below them on the symmetry plane;
- seat: 4 mm below the top of the highest region behind the wheelbase middle.
Every finder returns None when there is nothing where it looks; validate() names it.
"""
import numpy as np

SEAT_DEPTH = 0.004


def steering_axis(X, fa, R):
    """(steer_bottom, steer_top) or None."""
    d = np.hypot(X[:, 0] - fa[0], X[:, 1] - fa[1])
    # metric floors: a scooter's 10 cm wheels carry a stem as thick as a bicycle's
    m = (d > 1.05 * R) & (X[:, 1] > fa[1]) & (X[:, 1] < fa[1] + max(4 * R, 1.2)) & (np.abs(X[:, 2]) < max(0.25 * R, 0.04)) \
        & (X[:, 0] > fa[0] - 2.5 * R) & (X[:, 0] < fa[0] + 1.0 * R)
    # every sample of the column region (of the caller's samples, the whole surface up to
    # shape_fit's cap): a subset of them here made the chosen line hinge on which points it kept
    # (two lines' counts nearly tie; a turned copy of a model kept other points)
    P = X[m][:, :2]
    if len(P) < 10:
        return None
    P = P - fa[:2]
    th = np.radians(np.arange(50, 89, 1.0))
    a = np.stack([-np.cos(th), np.sin(th)], 1)          # up and back
    nrm = np.stack([a[:, 1], -a[:, 0]], 1)              # towards the front
    offs = np.arange(-0.3, 0.301, 0.02) * R
    band = max(0.06 * R, 0.015)
    # counts[offset, angle] of samples within band of each line above the tyre: two binary
    # searches per angle, not an (n, angles) comparison per offset
    counts = np.zeros((len(offs), len(th)), np.int64)
    for k in range(len(th)):
        dk = np.sort((P @ nrm[k])[P @ a[k] > 1.0 * R])
        counts[:, k] = np.searchsorted(dk, offs + band, "left") - np.searchsorted(dk, offs - band, "right")
    j, k = np.unravel_index(int(np.argmax(counts)), counts.shape)   # the first maximum, offset-major
    if counts[j, k] < 5:
        return None
    o = offs[j]
    dist, along = P @ nrm[k], P @ a[k]
    hit = (np.abs(dist - o) < band) & (along > 1.0 * R)
    t = np.sort(along[hit])
    # the contiguous run of surface along the line, starting above the tyre
    gaps = np.nonzero(np.diff(t) > max(0.3 * R, 0.05))[0]
    top = t[gaps[0]] if len(gaps) else t[-1]
    base = fa[:2] + o * nrm[k]
    t0 = 1.15 * R
    t1 = max(top - 0.03 * R, t0 + 0.15 * R)
    ax = np.array([a[k, 0], a[k, 1], 0.0])
    b3 = np.array([base[0], base[1], 0.0])
    return b3 + t0 * ax, b3 + t1 * ax


def head_zone(X, sb, st, R):
    """(start, end) along the steering axis from steer_bottom of the head tube: where the frame's
    tubes (or body) join the axis from behind, on the symmetry plane, above the front tyre.  A
    bicycle's head tube starts just above the tyre, a motorcycle's 70 cm up its fork; without
    frame joints: the 15 cm (for 35 cm wheels) above steer_bottom."""
    a = (st - sb) / np.linalg.norm(st - sb)
    back = np.array([-a[1], a[0], 0.0])            # perpendicular to the axis, towards the rear
    fa_far = np.hypot(X[:, 0] - (sb[0] - 1.15 * R * a[0]), X[:, 1] - (sb[1] - 1.15 * R * a[1])) > 1.2 * R
    d = X - sb
    t, off = d @ a, d @ back
    m = fa_far & (np.abs(X[:, 2]) < max(0.04, 0.1 * R)) & (off > max(0.05, 0.15 * R)) & (off < max(0.08, 0.3 * R)) \
        & (t > -0.2 * R) & (t < np.linalg.norm(st - sb))
    default = (0.0, 0.15 * R / 0.35)
    if m.sum() < 10:
        return default
    tt = np.sort(t[m])
    lo, hi = float(np.percentile(tt, 2)), float(np.percentile(tt, 98))
    if hi - lo < 0.02:
        return default
    return max(0.0, lo - 0.02), hi + 0.02


def handles(X, steer_top, seat_x, R):
    m = (X[:, 1] > steer_top[1] - 0.5 * R) & (X[:, 0] > seat_x + 0.3 * R) & (X[:, 0] < steer_top[0] + 1.5 * R)
    B = X[m]
    if len(B) < 4 or B[:, 2].max() < 0.2 * R or B[:, 2].min() > -0.2 * R:
        return None
    out = []
    for sg in (1, -1):
        z = sg * B[:, 2]
        zmax = z.max()
        grip = B[(z > zmax - 0.35 * R) & (z < zmax - 0.1 * R)]
        if len(grip) == 0:
            grip = B[z > zmax - 0.35 * R]
        out.append(np.array([grip[:, 0].mean(), grip[:, 1].mean(), sg * (zmax - 0.2 * R)]))
    r, l = out
    # a mirror-symmetric pair (the rig and validation expect one)
    xy = 0.5 * (r[:2] + l[:2])
    w = 0.5 * (r[2] - l[2])
    return np.array([xy[0], xy[1], -w]), np.array([xy[0], xy[1], w])


def bulky(X, fa, ra, R, cell=0.02):
    """Share of the side view between the wheels (axle height to wheel top) filled by a wide
    body: cells with surface on both sides of the bike's plane, beyond 0.15 R.  A motorcycle's
    engine and tank or a scooter's deck fill 0.46-0.8 of it; a bicycle's tubes, chainring and
    crank arms (one side each) <= 0.1, even a toy bike's thick tubes, whose plain side-view
    fill (0.66) is a motorcycle's."""
    x0, x1, y0, y1 = ra[0] + R, fa[0] - R, 0.5 * R + 0.5 * (fa[1] + ra[1]) - R, 2 * R
    if x1 - x0 < 2 * cell or y1 - y0 < 2 * cell:
        return 0.0
    m = (X[:, 0] > x0) & (X[:, 0] < x1) & (X[:, 1] > y0) & (X[:, 1] < y1)
    t = 0.15 * R

    def cells(Y):
        ij = np.floor((Y[:, :2] - [x0, y0]) / cell).astype(np.int64)
        return np.unique(ij[:, 0] * 100003 + ij[:, 1])

    both = np.intersect1d(cells(X[m & (X[:, 2] > t)]), cells(X[m & (X[:, 2] < -t)]))
    return len(both) / (np.ceil((x1 - x0) / cell) * np.ceil((y1 - y0) / cell))


def _blobs(S, cell):
    """Connected groups (26-neighbour cells of size `cell`) of the points S: list of index arrays."""
    ij = np.floor(S / cell).astype(np.int64)
    keys, inv = np.unique(ij, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    where = {tuple(k): n for n, k in enumerate(keys)}
    group = -np.ones(len(keys), int)
    offs = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    g = 0
    for n in range(len(keys)):
        if group[n] >= 0:
            continue
        group[n] = g
        stack = [n]
        while stack:
            k = keys[stack.pop()]
            for o in offs:
                m = where.get((k[0] + o[0], k[1] + o[1], k[2] + o[2]))
                if m is not None and group[m] < 0:
                    group[m] = g
                    stack.append(m)
        g += 1
    lab = group[inv]
    return [np.nonzero(lab == k)[0] for k in range(g)]


def _pedal_candidates(X, fa, ra, R, zmin, sg):
    """Per side (sg +1 right, -1 left): the outer ends of the separate things sticking out
    sideways (beyond zmin) around the crank: (x, y, outer |z|) of each outer end that is compact
    (a pedal; not a kickstand's foot on the ground, a pannier, a cargo box's wall or a
    stabiliser wheel) and lies between the wheels.  Each group's outer layer (0.12 R deep) is
    split in the side view; a group whose layer holds nothing like a pedal is peeled and looked
    at again (a kickstand touching a pedal)."""
    m = (X[:, 0] > ra[0] - R) & (X[:, 0] < fa[0] + R) & (X[:, 1] < max(fa[1], ra[1]) + R) & (sg * X[:, 2] > zmin)
    S = X[m]
    out = []
    if len(S) < 4:
        return out
    for g in _blobs(S, max(0.1 * R, 0.025)):
        B = S[g]
        for _ in range(4):   # peel the outer layer until it holds a pedal (a stand may touch one)
            if len(B) == 0:
                break
            z = sg * B[:, 2]
            in_cap = z > z.max() - 0.12 * R
            found = False
            for h in _blobs(B[in_cap] * [1.0, 1.0, 0.0], max(0.1 * R, 0.025)):
                cap = B[in_cap][h]
                lo, hi = cap.min(0), cap.max(0)
                c = 0.5 * (lo + hi)
                if np.hypot(*(hi - lo)[:2]) > R or c[1] < 0.25 * R:
                    continue
                if ra[0] + 0.5 * R < c[0] < fa[0] - 0.5 * R and c[1] < max(fa[1], ra[1]) + 0.6 * R:
                    out.append((c[0], c[1], float((sg * cap[:, 2]).max())))
                    found = True
            if found:
                break
            B = B[~in_cap]
    return out


def _inset(z_outer, R):
    """|Z| of a pedal body's centre from its outer end's: 0.14 R in, at most half way to the plane."""
    return max(z_outer - 0.14 * R, 0.5 * z_outer)


def pedals(X, fa, ra, R, tyre_half_width):
    """(crank_axle, pedal_left, pedal_right, has_crank) or None.  The pedals are the outermost
    pair of compact things sticking out sideways between the wheels that sit point-symmetric
    about a crank axle (apart in the side view, as far out on both sides); footrests (a
    motorcycle's pegs, a scooter's deck) coincide in the side view.  A wide body between the
    wheels (a motorcycle) has footrests, not a crank."""
    zmin = tyre_half_width + 0.05 * R
    right = _pedal_candidates(X, fa, ra, R, zmin, 1)
    left = _pedal_candidates(X, fa, ra, R, zmin, -1)
    pairs = [(min(r[2], l[2]), r, l) for r in right for l in left if abs(r[2] - l[2]) < 0.15 * R]
    crank = [p for p in pairs if 0.35 * R < np.hypot(p[1][0] - p[2][0], p[1][1] - p[2][1]) < 1.6 * R]
    if not pairs:
        # uneven pedals (a toy's, 4.7 cm apart in reach) near the limit: the bike's plane comes
        # from the tyre bands and moves a few mm between copies of one model (turned, other
        # pixel grid), enough to cross it; a crank-like pair within 0.25 R is still taken
        # rather than the outermost surface (the robot bike's crank axle moved 5.5 cm)
        crank = [(min(r[2], l[2]), r, l) for r in right for l in left if abs(r[2] - l[2]) < 0.25 * R
                 and 0.35 * R < np.hypot(r[0] - l[0], r[1] - l[1]) < 1.6 * R]
    pick = max(crank or pairs, key=lambda p: p[0], default=None)
    if pick is None and bool(right) != bool(left):
        # one side's pedal or peg is lost in something longer (an exhaust along it): mirror the
        # other side's (a footrest pair; a crank needs both)
        one = max(right or left, key=lambda c: c[2])
        pick = (one[2], one, one)
    if pick is not None:
        (xr, yr, zr), (xl, yl, zl) = pick[1], pick[2]
        # the pedal body's centre: about 5 cm (0.14 R) in from its outer end, and never across the
        # bike's plane (a narrow child's pedal ending 4 cm out stays on its own side)
        ends = [np.array([xr, yr, _inset(zr, R)]), np.array([xl, yl, -_inset(zl, R)])]
    else:   # nothing compact on both sides: the outermost surface per side
        m = (X[:, 0] > ra[0] + 0.5 * R) & (X[:, 0] < fa[0] - 0.5 * R) & (X[:, 1] < max(fa[1], ra[1]) + 0.6 * R)
        B = X[m]
        if len(B) < 4:
            return None
        ends = []
        for sg in (1, -1):
            z = sg * B[:, 2]
            zmax = z.max()
            if zmax < zmin:
                return None
            c = B[z > zmax - 0.12 * R]
            lo, hi = c.min(0), c.max(0)
            ends.append(np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), sg * _inset(zmax, R)]))
    pr, pl = ends
    sep = np.linalg.norm(pr[:2] - pl[:2])
    ca = np.array([0.5 * (pr[0] + pl[0]), 0.5 * (pr[1] + pl[1]), 0.0])
    has_crank = 0.35 * R < sep < 1.6 * R and bulky(X, fa, ra, R) < 0.3
    if has_crank:  # exactly opposite about the axle (the rig rotates them as one)
        v = 0.5 * (pr[:2] - pl[:2])
        pr = np.array([ca[0] + v[0], ca[1] + v[1], pr[2]])
        pl = np.array([ca[0] - v[0], ca[1] - v[1], pl[2]])
    else:
        pr = np.array([ca[0], ca[1], pr[2]])
        pl = np.array([ca[0], ca[1], pl[2]])
    return ca, pl, pr, has_crank


def seat(X, fa, ra, R):
    mid = 0.5 * (fa[0] + ra[0])
    m = (X[:, 0] > ra[0] - 0.3 * R) & (X[:, 0] < mid + 0.15 * R) & (np.abs(X[:, 2]) < 0.3 * R)
    B = X[m]
    if len(B) == 0:
        return None
    top = B[:, 1].max()
    if top < max(fa[1], ra[1]) + 0.2 * R:
        return None
    cap = B[B[:, 1] > top - 0.08 * R]
    xc = 0.5 * (cap[:, 0].min() + cap[:, 0].max())
    return np.array([xc, top - SEAT_DEPTH, 0.0])

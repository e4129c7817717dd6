"""Automatic part labels from the keypoints (numpy, no bpy).

Every point of space gets a region from the keypoints (canonical metres):
- crank: within the crank radius of the pedal axle and outside the bottom-bracket shell's
  width (|Z| > BB_HALF), or on the axle itself;
- steering: the front wheel disc, the fork between the front axle and the head tube, the
  steerer inside the head tube (closer to the axis than the head tube wall), and the cockpit
  above and in front of the saddle nose;
- frame: the rest.
A connected component takes the crank or steering label only if (almost) all of its surface
lies in that region: rigid parts are whole pieces in real models, and a frame tube that merely
reaches into a region (a chain stay next to the chainring) stays on the frame.  With keypoints from the shape
(a real model), a piece mostly (60 %) in the steering regions, less than half in the head-tube
zone (not the head tube), that never reaches back to the saddle is a one-piece fork, stem and
bar: all steering.  A large
component that lies across regions (a fused single-mesh model) is labelled per face instead.
"""
import numpy as np

FRAME, STEERING, CRANK, JUNK = 0, 1, 2, -1
PART_NAMES = {FRAME: "frame", STEERING: "steering", CRANK: "crank"}
BB_HALF = 0.036        # half the bottom-bracket shell width (68-73 mm shells)
WHOLE = 0.97           # share of a component's area that must lie in a region
FUSED = 0.05           # components above this share of the bike's area may be cut
MOSTLY = 0.6           # a piece this much in the steering regions, ahead of the saddle, steers


def _head_range(head_span, span):
    """(start, end) of the head tube along the axis from steer_bottom: the whole steer_bottom ->
    steer_top span, or head_span's (start, end), or its length from steer_bottom."""
    if head_span is None:
        return 0.0, span
    if np.ndim(head_span):
        return float(head_span[0]), min(span, float(head_span[1]))
    return 0.0, min(span, float(head_span))


def regions(X, kp, head_radius=None, wheel_radius=None, head_span=None, with_head=False):
    """Region label (FRAME/STEERING/CRANK) per canonical point X (n, 3); with_head: also the
    bool mask of points in the head-tube zone.  head_span: (start, end) of the head tube along
    the axis from steer_bottom (or its length from steer_bottom) when steer_top marks the stem
    top instead (shape-based keypoints); the fork region then reaches up to its start.
    Cylinders are regular polygons (poly_radius), exactly the prisms cut_planes cuts along."""
    X = np.asarray(X, float)
    out = np.full(len(X), FRAME)
    ca, fa = kp["crank_axle"], kp["front_axle"]
    sb, st = kp["steer_bottom"], kp["steer_top"]
    R = wheel_radius if wheel_radius is not None else fa[1]
    r_ht = head_radius if head_radius else 0.02
    # crank
    rc = max(np.hypot(*(kp[p][:2] - ca[:2])) for p in ("pedal_left", "pedal_right")) + 0.07
    z = np.array([0, 0, 1.0])
    cz = np.array([ca[0], ca[1], 0.0])
    # a point on the shell's end plane (a face lying in it: a shell modelled exactly 72 mm wide)
    # is the shell's, within float noise, so all its corners fall on one side
    crank = ((poly_radius(X, cz, z, 24) < rc) & (np.abs(X[:, 2]) > BB_HALF + 1e-7)) | \
        ((poly_radius(X, cz, z, 12) < 0.016) & (np.abs(X[:, 2]) < rc))
    # steering
    a = (st - sb) / np.linalg.norm(st - sb)
    span = np.linalg.norm(st - sb)
    t = (X - sb) @ a
    rho = poly_radius(X, sb, a, 12)
    h0, h1 = _head_range(head_span, span)
    in_head = (t >= h0) & (t <= h1) & (rho < r_ht + 0.012)
    # margins in metres for a bicycle's 0.35 m wheel radius, shrunk with smaller wheels (a kick
    # scooter's 10 cm wheels sit a few cm from its deck and neck)
    k = min(1.0, R / 0.35)
    steer = np.zeros(len(X), bool)
    steer |= (poly_radius(X, np.array([fa[0], fa[1], 0.0]), z, 24) < R + 0.03 * k) & (np.abs(X[:, 2]) < 0.15)
    # the fork: a slab along the line from the front axle to the head tube's bottom
    hb = sb + h0 * a
    f2 = (hb - fa) / np.linalg.norm(hb - fa)
    side = np.array([f2[1], -f2[0], 0.0])
    steer |= (np.abs((X - fa) @ side) < 0.07 * k) & ((X - fa) @ f2 > -0.07 * k) & (np.abs(X[:, 2]) < 0.15) & (t < h0)
    # on the axis above the head tube: steerer, spacers and stem (a scooter's stem is 80 cm long)
    steer |= (t > h1) & (rho < max(0.04, 2 * r_ht))
    cockpit_x = kp["seat"][0] + 0.15 if "seat" in kp else ca[0] + 0.1
    cockpit = (X[:, 1] > st[1] - 0.16) & (X[:, 0] > cockpit_x)
    if head_span is not None:
        # keypoints from the shape (a real model, maybe one fused body): the cockpit is what
        # sits near the steering axis, not a motorcycle's tank behind it
        # sits near the steering axis in the side view (a bar is wide across, a tank is behind)
        d2 = X[:, :2] - sb[:2]
        a2 = a[:2] / np.linalg.norm(a[:2])
        cockpit &= np.abs(d2[:, 0] * a2[1] - d2[:, 1] * a2[0]) < 0.3
    steer |= cockpit
    steer = np.where(in_head, rho < 0.8 * r_ht, steer)
    out[steer] = STEERING
    out[crank & ~steer] = CRANK
    return (out, in_head) if with_head else out


def label_triangles(view, keep_tri, kp, head_radius=None, wheel_radius=None, has_crank=True, head_span=None):
    """Part label per triangle of view.soup (JUNK for triangles outside the kept assembly).

    Returns (labels (m,), per-face flag `cut` (m,) True where a fused component was labelled
    per face)."""
    soup = view.soup
    reg = regions(view.tri_c, kp, head_radius, wheel_radius, head_span)
    # votes use 7 points per triangle (corners, edge midpoints, centroid): a long tube face
    # that reaches into a region then counts only the part that lies inside it
    tri = view.P[soup.TW]
    bary = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [.5, .5, 0], [.5, 0, .5], [0, .5, .5], [1 / 3, 1 / 3, 1 / 3]])
    samples = np.einsum("kj,mjd->mkd", bary, tri).reshape(-1, 3)
    vote, head = regions(samples, kp, head_radius, wheel_radius, head_span, with_head=True)
    vote = vote.reshape(len(tri), len(bary))
    head = head.reshape(len(tri), len(bary)).mean(1)
    if not has_crank:
        reg[reg == CRANK] = FRAME
        vote[vote == CRANK] = FRAME
    lab = np.full(len(soup.TW), JUNK)
    cut = np.zeros(len(soup.TW), bool)
    total = view.area[keep_tri].sum()
    front_of_saddle = (kp["seat"][0] + 0.1) if "seat" in kp else kp["crank_axle"][0]
    shape_kp = head_span is not None   # keypoints from the shape: pieces need not follow our conventions
    crank_r = max(np.hypot(*(kp[p][:2] - kp["crank_axle"][:2])) for p in ("pedal_left", "pedal_right")) + 0.07
    for c in view.comps:
        ti = c.tris
        a = view.area[ti]
        A = a.sum()
        if A <= 0:
            lab[ti] = FRAME
            continue
        v = vote[ti]
        share = np.array([(a[:, None] * (v == k)).sum() for k in (FRAME, STEERING, CRANK)]) / (A * v.shape[1])
        xmin = view.P[c.verts, 0].min()
        reach = np.hypot(*(view.P[c.verts, :2] - kp["crank_axle"][:2]).T).max()
        if share[CRANK] >= WHOLE or (has_crank and crank_r - 0.07 > reach > 0.05 and share[STEERING] == 0):
            # a piece within the crank's reach around the axle and bigger than the bottom
            # bracket shell: a chainring, spider or arm (they may sit inside the shell's width)
            lab[ti] = CRANK
        elif share[STEERING] >= WHOLE or (shape_kp and share[STEERING] >= MOSTLY and share[CRANK] < 0.03
                                          and xmin > front_of_saddle
                                          and (a * head[ti]).sum() < 0.5 * A):
            # a piece mostly in the steering regions that stays ahead of the saddle is the fork /
            # stem / bar in one piece (its steerer passes through the head-tube zone, which
            # alone would call it frame)
            lab[ti] = STEERING
        elif share[STEERING] < 0.02 and _chain_guard(view.P[c.verts], kp["crank_axle"], crank_r):
            # a flat plate on the drive side reaching back past the crank: a chain guard or the
            # chain itself (frame), not a crank fused to the frame
            lab[ti] = FRAME
        elif A > FUSED * total and share.max() < WHOLE and np.sort(share)[-2] > 0.02:
            lab[ti] = reg[ti]
            cut[ti] = True
        else:
            lab[ti] = FRAME
    return lab, cut


def _chain_guard(p, ca, crank_r):
    """A piece on one side of the bike (all of it beyond the bottom-bracket shell), thin across
    (< 6 cm) and reaching behind the crank's circle: a chain guard or a chain loop."""
    z = p[:, 2]
    one_side = (z.min() > BB_HALF) or (z.max() < -BB_HALF)
    return bool(one_side and z.max() - z.min() < 0.06 and p[:, 0].min() < ca[0] - crank_r)


def _directions(axis, n):
    axis = axis / np.linalg.norm(axis)
    u = np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    k = 2 * np.pi * np.arange(n) / n
    return np.cos(k)[:, None] * u + np.sin(k)[:, None] * w


def poly_radius(X, centre, axis, n):
    """The 'radius' of points X about an axis measured by a regular n-gon (max over its face
    normals of the offset): a cylinder test that a cut along n planes reproduces exactly."""
    return ((np.asarray(X, float) - centre) @ _directions(axis, n).T).max(1)


def _prism(centre, axis, radius, n):
    """n planes (point, outward normal) tangent to a cylinder of `radius` about `axis` through
    `centre`: a cut along them approximates the cylinder within radius * (1 - cos(pi / n))."""
    return [(centre + radius * d, d) for d in _directions(axis, n)]


def cut_planes(kp, head_radius=None, wheel_radius=None, head_span=None):
    """Planes (point, unit normal), canonical metres, along the boundaries of regions(): cutting
    a fused mesh's faces along them leaves every piece on one side of each boundary, so the
    parts are clean rigid pieces (cylinders as prisms of 12-24 planes)."""
    ca, fa = np.asarray(kp["crank_axle"], float), np.asarray(kp["front_axle"], float)
    sb, st = np.asarray(kp["steer_bottom"], float), np.asarray(kp["steer_top"], float)
    R = wheel_radius if wheel_radius is not None else fa[1]
    r_ht = head_radius if head_radius else 0.02
    a = (st - sb) / np.linalg.norm(st - sb)
    span = np.linalg.norm(st - sb)
    h0, h1 = _head_range(head_span, span)
    k = min(1.0, R / 0.35)
    z = np.array([0, 0, 1.0])
    planes = [(sb + h0 * a, a), (sb + h1 * a, a)]                 # head tube ends
    planes += _prism(sb, a, r_ht + 0.012, 12)                       # head tube wall
    planes += _prism(sb, a, 0.8 * r_ht, 12)                         # steerer inside it
    planes += _prism(sb, a, max(0.04, 2 * r_ht), 12)                # steerer / stem above it
    planes += _prism(np.array([fa[0], fa[1], 0.0]), z, R + 0.03 * k, 24)   # front wheel disc
    planes += [(np.array([0, 0, 0.15]), z), (np.array([0, 0, -0.15]), z)]
    hb = sb + h0 * a
    f2 = (hb - fa) / np.linalg.norm(hb - fa)
    side = np.array([f2[1], -f2[0], 0.0])
    planes += [(fa + 0.07 * k * side, side), (fa - 0.07 * k * side, side), (fa - 0.07 * k * f2, f2)]   # fork slab
    cockpit_x = kp["seat"][0] + 0.15 if "seat" in kp else ca[0] + 0.1
    planes += [(np.array([0, st[1] - 0.16, 0]), np.array([0, 1.0, 0])),
               (np.array([cockpit_x, 0, 0]), np.array([1.0, 0, 0]))]
    a2 = np.array([a[1], -a[0], 0.0]) / np.linalg.norm(a[:2])
    planes += [(sb + 0.3 * a2, a2), (sb - 0.3 * a2, a2)]             # cockpit near the axis
    if all(p in kp for p in ("pedal_left", "pedal_right")):
        rc = max(np.hypot(*(np.asarray(kp[p], float)[:2] - ca[:2])) for p in ("pedal_left", "pedal_right")) + 0.07
        planes += _prism(np.array([ca[0], ca[1], 0.0]), z, rc, 24)  # crank disc
        planes += [(np.array([0, 0, BB_HALF]), z), (np.array([0, 0, -BB_HALF]), z)]
        planes += _prism(np.array([ca[0], ca[1], 0.0]), z, 0.016, 12)   # the axle itself
        planes += [(np.array([0, 0, rc]), z), (np.array([0, 0, -rc]), z)]
    return [(np.asarray(p, float), np.asarray(n, float) / np.linalg.norm(n)) for p, n in planes]

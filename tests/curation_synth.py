"""Synthetic two-wheelers (and things that are not) built from primitives, numpy only, for the
curation tests: not our procedural generator's pieces, so the curation cannot lean on its
conventions.  Every factory returns the truth it was built from (keypoints, a part label per
triangle); tests compare the curation against that, never against the code under test.

Kinds: a city bike with any tyre segment count, fat tyres, with or without chainring, a chain
guard around the ring, a rider, a third wheel beside the rear or front one (tricycles), a big
front wheel (penny-farthing); a kick scooter (small fat wheels, deck, T-bar); a motorcycle
(fat tyres, a bulky body between the wheels, footpegs); a noisy photogrammetry-like scan; and
fuse() / transform() to make any of them one connected mesh, rotated, off-origin, in other units.
"""
import numpy as np

from addon.core.curation import mesh

FRAME, STEER, CRANK, RIDER = 0, 1, 2, 3


class Builder:
    def __init__(self):
        self.V, self.T, self.lab, self.n = [], [], [], 0

    def add(self, V, T, lab):
        self.V.append(np.asarray(V, float))
        self.T.append(np.asarray(T) + self.n)
        self.lab += list(np.broadcast_to(lab, (len(T),)))
        self.n += len(V)

    def torus(self, c, R, r, nseg, ntube, lab, normal_z=True, arc=None, flat=1.0):
        """A torus in the XY plane; arc=(a0, a1) radians: an open strip of it (a mudguard);
        flat scales the tube's radial thickness."""
        a = np.linspace(0, 2 * np.pi, nseg, endpoint=False) if arc is None else np.linspace(arc[0], arc[1], nseg)
        b = np.linspace(0, 2 * np.pi, ntube, endpoint=False)
        A, B = np.meshgrid(a, b, indexing="ij")
        rr = R - r + flat * r * np.cos(B)
        V = np.stack([rr * np.cos(A), rr * np.sin(A), r * np.sin(B)], -1).reshape(-1, 3) + c
        T = []
        for i in range(nseg if arc is None else nseg - 1):
            for j in range(ntube):
                p, q = i * ntube + j, ((i + 1) % nseg) * ntube + j
                p2, q2 = i * ntube + (j + 1) % ntube, ((i + 1) % nseg) * ntube + (j + 1) % ntube
                T += [(p, q, q2), (p, q2, p2)]
        self.add(V, T, lab)

    def tube(self, a, b, r, lab, n=8):
        a, b = np.asarray(a, float), np.asarray(b, float)
        d = (b - a) / np.linalg.norm(b - a)
        u = np.cross(d, [0, 0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0, 0])
        u /= np.linalg.norm(u)
        w = np.cross(d, u)
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        ring = r * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * w)
        V = np.concatenate([a + ring, b + ring, [a, b]])
        T = []
        for i in range(n):
            j = (i + 1) % n
            T += [(i, j, n + j), (i, n + j, n + i), (2 * n, j, i), (2 * n + 1, n + i, n + j)]
        self.add(V, T, lab)

    def box(self, c, h, lab):
        c, h = np.asarray(c, float), np.asarray(h, float)
        s = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        V = c + s * h
        T = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
        self.add(V, T, lab)

    def ellipsoid(self, c, h, lab, n=24):
        """A closed UV ellipsoid of half axes h (dense: a sculpted saddle's many vertices)."""
        u, v = np.meshgrid(np.linspace(0, np.pi, n + 1)[1:-1], np.linspace(0, 2 * np.pi, 2 * n, endpoint=False),
                           indexing="ij")
        P = np.stack([np.sin(u) * np.cos(v), np.cos(u), np.sin(u) * np.sin(v)], -1).reshape(-1, 3)
        V = np.concatenate([P, [[0, 1, 0], [0, -1, 0]]]) * h + c
        T, m = [], 2 * n
        for i in range(n - 2):
            for j in range(m):
                p, q = i * m + j, i * m + (j + 1) % m
                T += [(p, q, q + m), (p, q + m, p + m)]
        top, bot = len(P), len(P) + 1
        T += [(top, (j + 1) % m, j) for j in range(m)] + [(bot, (n - 3) * m + j, (n - 3) * m + (j + 1) % m) for j in range(m)]
        self.add(V, T, lab)

    def arrays(self):
        return np.concatenate(self.V), np.concatenate(self.T), np.array(self.lab)


def synth_bike(nseg=24, tyre_r=0.022, rider=False, chainring=True, third_wheel=None, front_R=0.35,
               chain_guard=False, front_twin=None, extras=(), wheelbase=1.07, crank_angle=180.0,
               crank_phase=30.0):
    """A city bike from primitives in the canonical frame; (V, T, labels, truth keypoints).

    rider: False; True (torso, head, arms to the bar, thighs: separate pieces); "legs" (also
    shins down to the pedals and a shoe on each pedal); "one_piece" (the same person fused into
    one connected mesh).
    extras: what real city, utility and children's bikes carry: "kickstand" (down on the
    ground), "basket" (wire basket on the bar, steers), "rack" (rear rack with two panniers),
    "mudguards" (touching the tyres), "stabilisers" (a child's training wheels), "tall_post"
    (saddle 30 cm higher), "cargo" (a long-john box between the saddle and the front wheel; with
    wheelbase ~1.8 and a smaller front wheel), "wide_saddle" (a cruiser's 32 cm saddle of many
    vertices instead of the box).
    crank_angle: the arms' angle apart; crank_phase: the right arm's angle from forward (+X),
    counter-clockwise seen from +Z (30: the right pedal ahead and up)."""
    b = Builder()
    R = 0.35
    ra, ca = np.array([-0.45, R, 0.0]), np.array([0.0, 0.29, 0.0])
    fa = np.array([wheelbase - 0.45 + max(front_R - R, 0), front_R, 0.0])
    for c, RR, lab in ((ra, R, FRAME), (fa, front_R, STEER)):
        b.torus(c, RR, tyre_r, nseg, 8, lab)
        b.torus(c, RR - tyre_r * 1.8, 0.008, nseg, 6, lab)           # rim
        for k in range(8):                                         # spokes
            ang = k * np.pi / 4
            b.tube(c + [0, 0, 0.02 * (-1) ** k], c + (RR - 0.05) * np.array([np.cos(ang), np.sin(ang), 0]), 0.002, lab, 4)
        b.tube(c - [0, 0, 0.05], c + [0, 0, 0.05], 0.015, lab)        # hub
    if third_wheel is not None:                                    # a tricycle's twin rear wheel
        b.torus(ra + [0, 0, third_wheel], R, tyre_r, nseg, 8, FRAME)
        b.tube(ra, ra + [0, 0, third_wheel], 0.015, FRAME)
    if front_twin is not None:                                     # a tadpole tricycle's twin front wheel
        b.torus(fa + [0, 0, front_twin], front_R, tyre_r, nseg, 8, STEER)
        b.tube(fa, fa + [0, 0, front_twin], 0.015, STEER)
    u = np.array([-np.cos(np.radians(70)), np.sin(np.radians(70)), 0.0])
    hb, ht = fa + 0.46 * u, fa + 0.62 * u
    for z in (-0.05, 0.05):                                        # fork legs
        b.tube(fa + [0, 0, z], fa + 0.42 * u + [0, 0, z], 0.012, STEER)
    b.tube(fa + 0.42 * u - [0, 0, 0.05], fa + 0.42 * u + [0, 0, 0.05], 0.015, STEER)   # crown
    b.tube(hb, ht, 0.022, FRAME)                                   # head tube
    stem = fa + 0.74 * u
    b.tube(ht, stem, 0.012, STEER)
    bar = stem + [0.06, 0.0, 0.0]
    b.tube(stem, bar, 0.012, STEER)
    # a one-piece bar swept back, no separate grips
    for s in (1, -1):
        b.tube(bar, bar + [-0.02, 0.01, s * 0.2], 0.011, STEER)
        b.tube(bar + [-0.02, 0.01, s * 0.2], bar + [-0.08, 0.02, s * 0.31], 0.013, STEER)
    seat_top = np.array([-0.2, 0.97 + (0.3 if "tall_post" in extras else 0.0), 0.0])
    st = seat_top - [0, 0.06, 0]
    b.tube(ca, st, 0.016, FRAME)                                   # seat tube + post
    if "wide_saddle" in extras:    # a cruiser's sprung saddle, 32 cm wide, densely modelled
        b.ellipsoid(seat_top - [0, 0.04, 0], [0.13, 0.04, 0.16], FRAME, 48)
    else:
        b.box(seat_top - [0, 0.03, 0], [0.12, 0.03, 0.07], FRAME)   # saddle
    b.tube(st - [0, 0.1, 0], ht, 0.016, FRAME)                     # top tube
    b.tube(ca, hb, 0.02, FRAME)                                    # down tube
    for z in (-0.045, 0.045):
        b.tube(ca + [0, 0, z], ra + [0, 0, z], 0.01, FRAME)          # chain stays
        b.tube(st - [0, 0.12, 0], ra + [0, 0, z], 0.01, FRAME)       # seat stays
    b.tube(ca - [0, 0, 0.036], ca + [0, 0, 0.036], 0.02, FRAME)     # bottom bracket shell
    ang = np.radians(crank_phase)   # the right arm's angle from forward (X), counter-clockwise seen from +Z
    v = 0.17 * np.array([np.cos(ang), np.sin(ang), 0])
    # crank_angle: the arms' angle apart (180 opposite; a model's arms at 170 are not)
    al = ang + np.radians(crank_angle)
    vl = 0.17 * np.array([np.cos(al), np.sin(al), 0])
    pr, pl = ca + v + [0, 0, 0.14], ca + vl - [0, 0, 0.14]
    b.tube(ca + [0, 0, 0.06], ca + v + [0, 0, 0.07], 0.01, CRANK)
    b.tube(ca - [0, 0, 0.06], ca + vl - [0, 0, 0.07], 0.01, CRANK)
    b.box(pr, [0.045, 0.012, 0.05], CRANK)
    b.box(pl, [0.045, 0.012, 0.05], CRANK)
    if chainring:
        b.torus(ca + [0, 0, 0.05], 0.1, 0.006, 32, 4, CRANK)
    if chain_guard:   # a closed box over the ring and the chain's top run (a city bike's chain case)
        b.box([-0.16, 0.31, 0.05], [0.3, 0.13, 0.012], FRAME)
    _extras(b, extras, ra, fa, ca, R, front_R, tyre_r, bar, hb)
    if rider:                                                      # a blocky person
        p = Builder() if rider == "one_piece" else b
        p.box([-0.1, 1.35, 0], [0.12, 0.3, 0.18], RIDER)            # torso
        p.box([-0.02, 1.8, 0], [0.1, 0.12, 0.09], RIDER)            # head
        for s in (1, -1):
            p.tube([-0.05, 1.55, s * 0.2], bar + [-0.08, 0.04, s * 0.27], 0.04, RIDER)   # arms
            p.tube([-0.15, 1.08, s * 0.1], [0.1, 0.7, s * 0.12], 0.06, RIDER)             # thighs
        if rider in ("legs", "one_piece"):   # shins down to the pedals, a shoe on each
            for s, ped in ((1, pr), (-1, pl)):
                p.tube([0.1, 0.7, s * 0.12], ped + [-0.02, 0.09, 0.0], 0.045, RIDER)
                p.box(ped + [0.03, 0.05, 0.0], [0.13, 0.038, 0.045], RIDER)
        if p is not b:                       # one connected mesh, as a scanned or sculpted person
            b.add(*fuse(*p.arrays())[:3])
    kp = {"front_axle": fa, "rear_axle": ra, "crank_axle": ca, "pedal_right": pr, "pedal_left": pl,
          "seat": seat_top - [0, 0.004, 0], "steer_bottom": hb, "steer_top": ht,
          "handle_right": bar + [-0.06, 0.017, 0.26], "handle_left": bar + [-0.06, 0.017, -0.26]}
    V, T, lab = b.arrays()
    return V, T, lab, kp


def _extras(b, extras, ra, fa, ca, R, front_R, tyre_r, bar, hb):
    if "kickstand" in extras:      # a side stand folded down onto the ground, left of the frame
        b.tube(ca + [-0.1, 0.0, -0.04], [-0.2, 0.0, -0.18], 0.01, FRAME)
        b.box([-0.2, 0.005, -0.18], [0.03, 0.005, 0.02], FRAME)
    if "basket" in extras:         # wire-basket walls on the bar (turns with it)
        c = bar + [0.2, -0.12, 0.0]
        for off, h in (([0, -0.12, 0], [0.15, 0.005, 0.17]), ([0.15, 0, 0], [0.005, 0.12, 0.17]),
                       ([-0.15, 0, 0], [0.005, 0.12, 0.17]), ([0, 0, 0.17], [0.15, 0.12, 0.005]),
                       ([0, 0, -0.17], [0.15, 0.12, 0.005])):
            b.box(c + off, h, STEER)
        b.tube(bar, c + [-0.15, 0.05, 0.0], 0.008, STEER)
    if "rack" in extras:           # rear rack over the tyre, two panniers hanging off it
        top = R + R + 0.08
        b.box([ra[0] + 0.05, top, 0.0], [0.22, 0.006, 0.07], FRAME)
        for z in (-0.07, 0.07):
            b.tube(ra + [0, 0, z], [ra[0] - 0.1, top, z], 0.006, FRAME)
            b.tube([ra[0] + 0.25, top, z], [-0.2, 0.78, z * 0.5], 0.006, FRAME)
        for z in (-0.19, 0.19):
            b.box([ra[0] + 0.02, top - 0.17, z], [0.17, 0.16, 0.06], FRAME)
    if "mudguards" in extras:      # strips over the tyres, touching them
        for c, RR, lab in ((ra, R, FRAME), (fa, front_R, STEER)):
            b.torus(c, RR + 0.012, 0.035, 20, 6, lab, arc=(np.radians(15), np.radians(165)), flat=0.3)
    if "stabilisers" in extras:    # a child's training wheels beside the rear wheel
        for z in (-0.22, 0.22):
            c = np.array([ra[0], 0.09, z])
            b.torus(c, 0.09, 0.015, 16, 6, FRAME)
            b.tube(ra + [0, 0, np.sign(z) * 0.05], c, 0.008, FRAME)
    if "cargo" in extras:          # a long-john cargo box low between the saddle and the front wheel
        x0, x1 = 0.25, fa[0] - front_R - 0.05
        b.box([(x0 + x1) / 2, 0.2, 0.0], [(x1 - x0) / 2, 0.01, 0.28], FRAME)
        for z in (-0.28, 0.28):
            b.box([(x0 + x1) / 2, 0.38, z], [(x1 - x0) / 2, 0.18, 0.008], FRAME)
        b.tube(ca, [x0, 0.2, 0.0], 0.02, FRAME)


def fuse(V, T, lab):
    """One connected mesh: each piece joined to the next by a sliver triangle (as fused scans and
    AI-made models are), sharing vertices."""
    s = mesh.Soup(V, T)
    comps = s.comp_of_vert
    extra = []
    inv, _ = mesh.weld(V)
    first = {}
    for i, c in enumerate(comps[inv]):
        first.setdefault(c, i)
    keys = sorted(first)
    for a, b in zip(keys[:-1], keys[1:]):
        i, j = first[a], first[b]
        extra.append((i, j, i))   # degenerate: zero area, but it links the pieces
    T2 = np.concatenate([T, np.array(extra)])
    return V, T2, np.concatenate([lab, np.full(len(extra), -1)])


def fuse_with_slivers(V, T, lab):
    """One connected mesh that a mesh editor accepts (no repeated corner): each piece joined to
    the nearest vertex of the pieces before it by a hair-thin triangle."""
    s = mesh.Soup(V, T)
    inv, _ = mesh.weld(V)
    comp = s.comp_of_vert[inv]
    keys = np.unique(comp)
    V2, extra = [np.asarray(V, float)], []
    n = len(V)
    done = np.isin(comp, keys[:1])
    for k in keys[1:]:
        mine = np.nonzero(comp == k)[0]
        other = np.nonzero(done)[0]
        d = np.linalg.norm(V[mine][:, None] - V[other][None], axis=2)
        i, j = np.unravel_index(np.argmin(d), d.shape)
        a, b = mine[i], other[j]
        V2.append([0.5 * (V[a] + V[b]) + [0, 0, 1e-5]])
        extra.append((a, b, n))
        n += 1
        done |= comp == k
    return np.concatenate(V2), np.concatenate([T, np.array(extra)]), np.concatenate([lab, np.full(len(extra), -1)])


def transform(V, seed, scale, offset):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    return scale * V @ q.T + offset, q




def synth_scooter(nseg=16, R=0.1, tyre_r=0.025):
    """A kick scooter: small fat wheels, a deck, a steep stem to a T-bar ~0.95 m up; no crank,
    no saddle.  Truth keypoints: axles and the steering axis (the head tube's ends)."""
    b = Builder()
    ra, fa = np.array([-0.36, R, 0.0]), np.array([0.42, R, 0.0])
    for c, lab in ((ra, FRAME), (fa, STEER)):
        b.torus(c, R, tyre_r, nseg, 8, lab)
        b.tube(c - [0, 0, 0.03], c + [0, 0, 0.03], 0.012, lab)          # hub
    b.box([0.0, 0.095, 0.0], [0.3, 0.015, 0.07], FRAME)                 # deck
    b.tube([-0.3, 0.095, 0.0], ra, 0.012, FRAME)                        # rear bracket
    u = np.array([-np.cos(np.radians(78)), np.sin(np.radians(78)), 0.0])
    hb = fa + (0.2 - fa[1]) / u[1] * u
    ht = hb + 0.1 * u
    b.tube([0.28, 0.095, 0.0], hb + [0.0, 0.02, 0.0], 0.02, FRAME)      # neck from the deck
    b.tube(hb, ht, 0.02, FRAME)                                          # head tube
    for z in (-0.03, 0.03):
        b.tube(fa + [0, 0, z], hb - 0.02 * u + [0, 0, z], 0.01, STEER)  # fork
    bar = fa + (0.95 - fa[1]) / u[1] * u
    b.tube(ht, bar, 0.014, STEER)                                        # stem
    b.tube(bar - [0, 0, 0.25], bar + [0, 0, 0.25], 0.012, STEER)         # T-bar, one piece
    kp = {"front_axle": fa, "rear_axle": ra, "steer_bottom": hb, "steer_top": ht}
    V, T, lab = b.arrays()
    return V, T, lab, kp


def synth_motorcycle(nseg=24, R=0.3, tyre_r=0.06, rider=False, extras=()):
    """A motorcycle: fat tyres, a bulky engine/tank/seat body filling the side view between the
    wheels, a swingarm, telescopic forks, a bar, footpegs.  extras: "triple" (triple-clamp plates
    across the fork legs and bar risers 12 cm above the top clamp: the bar, not the head tube,
    is the top of the steering), "fairing" (a frame-mounted nose fairing around the head and a
    windscreen), "exhaust" (a long silencer low on the right), "pillion" (passenger pegs
    behind the rider's)."""
    b = Builder()
    ra, fa = np.array([-0.7, R, 0.0]), np.array([0.75, R, 0.0])
    for c, lab in ((ra, FRAME), (fa, STEER)):
        b.torus(c, R, tyre_r, nseg, 10, lab)
        b.torus(c, R - 2 * tyre_r, 0.015, nseg, 6, lab)                  # rim
        b.tube(c - [0, 0, 0.08], c + [0, 0, 0.08], 0.05, lab)            # hub / disc
        for k in range(5):                                               # cast spokes
            ang = k * 2 * np.pi / 5
            b.tube(c, c + (R - 2 * tyre_r) * np.array([np.cos(ang), np.sin(ang), 0]), 0.015, lab, 6)
    b.box([0.0, 0.45, 0.0], [0.3, 0.17, 0.14], FRAME)                    # engine
    b.box([0.12, 0.8, 0.0], [0.25, 0.12, 0.16], FRAME)                   # tank
    b.box([-0.38, 0.8, 0.0], [0.26, 0.05, 0.13], FRAME)                  # seat
    for z in (-0.1, 0.1):
        b.tube([-0.1, 0.4, z], ra + [0, 0, z], 0.03, FRAME)              # swingarm
    u = np.array([-np.cos(np.radians(64)), np.sin(np.radians(64)), 0.0])
    hb, ht = fa + 0.72 * u, fa + 0.89 * u
    b.tube([0.05, 0.84, 0.0], hb + 0.05 * u, 0.035, FRAME)               # frame spine to the head
    b.tube(hb, ht, 0.035, FRAME)                                          # head tube
    for z in (-0.1, 0.1):
        b.tube(fa + [0, 0, z], hb + [0, 0, z], 0.025, STEER)             # fork legs
    b.tube(hb - [0, 0, 0.12], hb + [0, 0, 0.12], 0.025, STEER)           # lower clamp
    bar = ht + 0.06 * u
    b.tube(ht, bar, 0.03, STEER)                                          # upper clamp / stem
    b.tube(bar - [0, 0, 0.36], bar + [0, 0, 0.36], 0.014, STEER)          # one-piece bar
    for s in (1, -1):
        b.tube([0.0, 0.34, s * 0.14], [0.0, 0.34, s * 0.24], 0.012, FRAME)   # footpegs
    if "triple" in extras:
        for t in (hb, ht):
            b.box(t + [0.03, 0.0, 0.0], [0.05, 0.015, 0.14], STEER)
        for z in (-0.06, 0.06):
            b.tube(ht + [0, 0, z], ht + 0.14 * u + [0, 0, z], 0.015, STEER)   # risers
        b.tube(ht + 0.14 * u - [0, 0, 0.36], ht + 0.14 * u + [0, 0, 0.36], 0.014, STEER)
    if "fairing" in extras:        # frame-mounted: it does not turn with the bar
        b.box(hb + [0.12, 0.02, 0.0], [0.1, 0.14, 0.2], FRAME)
        b.box(ht + [0.14, 0.2, 0.0], [0.01, 0.14, 0.18], FRAME)          # windscreen
        b.tube(hb + [0.02, 0.0, 0.0], hb + [0.1, 0.0, 0.0], 0.02, FRAME)
    if "exhaust" in extras:
        b.tube([0.15, 0.3, 0.16], [-0.7, 0.42, 0.2], 0.05, FRAME)
    if "pillion" in extras:
        for s in (1, -1):
            b.tube([-0.4, 0.5, s * 0.14], [-0.4, 0.5, s * 0.24], 0.012, FRAME)
    if rider:   # a blocky person on the seat: torso, head, arms to the grips, thighs over the tank
        b.box([-0.2, 1.25, 0], [0.15, 0.3, 0.18], RIDER)
        b.box([-0.1, 1.7, 0], [0.12, 0.13, 0.12], RIDER)
        for s in (1, -1):
            b.tube([-0.05, 1.45, s * 0.2], [0.3, 1.17, s * 0.33], 0.045, RIDER)
            b.tube([-0.3, 0.95, s * 0.12], [0.05, 0.6, s * 0.2], 0.07, RIDER)
    kp = {"front_axle": fa, "rear_axle": ra, "steer_bottom": hb, "steer_top": ht}
    V, T, lab = b.arrays()
    return V, T, lab, kp


def noisy_scan(sigma=0.02, step=0.03, seed=0):
    """A photogrammetry-like scan of the city bike: its surface re-meshed into small triangles,
    every vertex displaced by N(0, sigma) metres, the wheels' spoke gaps filled with a noisy
    membrane, a patch of ground under it, all one connected mesh."""
    rng = np.random.default_rng(seed)
    V, T, _, kp = synth_bike(nseg=24)
    tri = V[T]
    longest = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2).max(1)
    Vs, Ts, n = [], [], 0
    for k in np.unique(np.clip(np.ceil(longest / step), 1, 40).astype(int)):
        sel = tri[np.clip(np.ceil(longest / step), 1, 40).astype(int) == k]
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        m = i + j <= k
        idx = -np.ones((k + 1, k + 1), int)
        idx[m] = np.arange(m.sum())
        bary = np.stack([i[m], j[m], k - i[m] - j[m]], 1) / k
        small = []
        for a in range(k):
            for c in range(k - a):
                small.append((idx[a, c], idx[a + 1, c], idx[a, c + 1]))
                if a + c + 1 < k:
                    small.append((idx[a + 1, c], idx[a + 1, c + 1], idx[a, c + 1]))
        small = np.array(small)
        pts = np.einsum("bk,tkd->tbd", bary, sel)
        for p in pts:
            Vs.append(p)
            Ts.append(small + n)
            n += len(p)
    # membranes across the wheels (a scan cannot see through spokes) and a ground patch
    for c in (kp["front_axle"], kp["rear_axle"]):
        r = np.sqrt(rng.uniform(0, 1, 600)) * 0.33
        a = rng.uniform(0, 2 * np.pi, 600)
        p = np.stack([c[0] + r * np.cos(a), c[1] + r * np.sin(a), np.zeros(600)], 1)
        Vs.append(p)
        Ts.append(_fan_cloud(p) + n)
        n += len(p)
    g = np.stack(np.meshgrid(np.linspace(-1.0, 1.2, 45), np.linspace(-0.5, 0.5, 21), indexing="ij"), -1).reshape(-1, 2)
    Vs.append(np.column_stack([g[:, 0], np.zeros(len(g)), g[:, 1]]))
    Ts.append(_grid_tris(45, 21) + n)
    V2 = np.concatenate(Vs)
    V2 = V2 + rng.normal(0, sigma, V2.shape)
    return fuse(V2, np.concatenate(Ts), np.zeros(sum(len(t) for t in Ts), int))[:2]


def _grid_tris(nx, ny):
    T = []
    for i in range(nx - 1):
        for j in range(ny - 1):
            p = i * ny + j
            T += [(p, p + ny, p + ny + 1), (p, p + ny + 1, p + 1)]
    return np.array(T)


def _fan_cloud(p):
    """Triangles joining each point of a planar cloud to its two nearest neighbours (a ragged
    membrane, as a scan's reconstruction of a spoked wheel is)."""
    d = np.linalg.norm(p[:, None, :2] - p[None, :, :2], axis=2)
    np.fill_diagonal(d, np.inf)
    nn = np.argsort(d, 1)[:, :2]
    return np.column_stack([np.arange(len(p)), nn[:, 0], nn[:, 1]])

"""Curation of varied synthetic two-wheelers built here from primitives (numpy, no bpy, fast).

Not our procedural generator's pieces: tyres of 10/16/33 segments, fat tyres, the whole bike
fused into one connected mesh, a one-piece handlebar (no separate grips), no chainring, a
rider-like extra shape, off-origin / rotated / cm / mm models; and the refusals (tricycle,
penny-farthing, frame without wheels, flat icon) with the check they name.  Truth keypoints
and part labels come from the construction, never from the code under test.
"""
import numpy as np
import pytest

from addon.core.curation import mesh, pipeline, split
from addon.core.script import UserError

FRAME, STEER, CRANK, RIDER = 0, 1, 2, 3


class Builder:
    def __init__(self):
        self.V, self.T, self.lab, self.n = [], [], [], 0

    def add(self, V, T, lab):
        self.V.append(np.asarray(V, float))
        self.T.append(np.asarray(T) + self.n)
        self.lab += [lab] * len(T)
        self.n += len(V)

    def torus(self, c, R, r, nseg, ntube, lab, normal_z=True):
        a = np.linspace(0, 2 * np.pi, nseg, endpoint=False)
        b = np.linspace(0, 2 * np.pi, ntube, endpoint=False)
        A, B = np.meshgrid(a, b, indexing="ij")
        rr = R - r + r * np.cos(B)
        V = np.stack([rr * np.cos(A), rr * np.sin(A), r * np.sin(B)], -1).reshape(-1, 3) + c
        T = []
        for i in range(nseg):
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

    def arrays(self):
        return np.concatenate(self.V), np.concatenate(self.T), np.array(self.lab)


def synth_bike(nseg=24, tyre_r=0.022, rider=False, chainring=True, third_wheel=None, front_R=0.35):
    """A city bike from primitives in the canonical frame; (V, T, labels, truth keypoints)."""
    b = Builder()
    R = 0.35
    ra, fa, ca = np.array([-0.45, R, 0.0]), np.array([0.62 + max(front_R - R, 0), front_R, 0.0]), np.array([0.0, 0.29, 0.0])
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
    seat_top = np.array([-0.2, 0.97, 0.0])
    st = seat_top - [0, 0.06, 0]
    b.tube(ca, st, 0.016, FRAME)                                   # seat tube + post
    b.box(seat_top - [0, 0.03, 0], [0.12, 0.03, 0.07], FRAME)       # saddle
    b.tube(st - [0, 0.1, 0], ht, 0.016, FRAME)                     # top tube
    b.tube(ca, hb, 0.02, FRAME)                                    # down tube
    for z in (-0.045, 0.045):
        b.tube(ca + [0, 0, z], ra + [0, 0, z], 0.01, FRAME)          # chain stays
        b.tube(st - [0, 0.12, 0], ra + [0, 0, z], 0.01, FRAME)       # seat stays
    b.tube(ca - [0, 0, 0.036], ca + [0, 0, 0.036], 0.02, FRAME)     # bottom bracket shell
    ang = np.radians(30)
    v = 0.17 * np.array([np.cos(ang), np.sin(ang), 0])
    pr, pl = ca + v + [0, 0, 0.14], ca - v - [0, 0, 0.14]
    b.tube(ca + [0, 0, 0.06], ca + v + [0, 0, 0.07], 0.01, CRANK)
    b.tube(ca - [0, 0, 0.06], ca - v - [0, 0, 0.07], 0.01, CRANK)
    b.box(pr, [0.045, 0.012, 0.05], CRANK)
    b.box(pl, [0.045, 0.012, 0.05], CRANK)
    if chainring:
        b.torus(ca + [0, 0, 0.05], 0.1, 0.006, 32, 4, CRANK)
    if rider:                                                      # a blocky person
        b.box([-0.1, 1.35, 0], [0.12, 0.3, 0.18], RIDER)            # torso
        b.box([-0.02, 1.8, 0], [0.1, 0.12, 0.09], RIDER)            # head
        for s in (1, -1):
            b.tube([-0.05, 1.55, s * 0.2], bar + [-0.08, 0.04, s * 0.27], 0.04, RIDER)   # arms
            b.tube([-0.15, 1.08, s * 0.1], [0.1, 0.7, s * 0.12], 0.06, RIDER)             # thighs
    kp = {"front_axle": fa, "rear_axle": ra, "crank_axle": ca, "pedal_right": pr, "pedal_left": pl,
          "seat": seat_top - [0, 0.004, 0], "steer_bottom": hb, "steer_top": ht,
          "handle_right": bar + [-0.06, 0.017, 0.26], "handle_left": bar + [-0.06, 0.017, -0.26]}
    V, T, lab = b.arrays()
    return V, T, lab, kp


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


def transform(V, seed, scale, offset):
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    return scale * V @ q.T + offset, q


def _check(V, T, lab, kp, scale=1.0, offset=0.0, seed=0, tol_kp=0.04, min_area=0.9):
    Vm, q = transform(V, seed, scale, offset)
    res = pipeline.curate_arrays(Vm, T, 0.7)
    assert res.problems == [], res.problems
    assert abs(res.scale * scale - 1) < 0.01
    Rm = res.M[:3, :3] / res.scale
    ang = np.degrees(np.arccos(np.clip((np.trace(Rm @ q) - 1) / 2, -1, 1)))
    assert ang < 1.0, ang
    err = {}
    for k, v in kp.items():
        if k in ("steer_bottom", "steer_top"):
            continue
        err[k] = float(np.linalg.norm(res.keypoints[k] - v))
    # the steering axis: the truth head tube ends lie on the estimated line
    a = res.keypoints["steer_top"] - res.keypoints["steer_bottom"]
    a /= np.linalg.norm(a)
    for k in ("steer_bottom", "steer_top"):
        d = kp[k] - res.keypoints["steer_bottom"]
        err[k + "_line"] = float(np.linalg.norm(d - (d @ a) * a))
    assert max(err.values()) < tol_kp, err
    area = mesh.triangle_areas(V, T)
    bike = (lab >= 0) & (lab != RIDER)
    right = area[bike & (res.labels == lab)].sum() / area[bike].sum()
    assert right >= min_area, right
    if (lab == RIDER).any():
        assert np.all(res.labels[lab == RIDER] == split.JUNK)
    return res, err, right


@pytest.mark.parametrize("nseg", [10, 16, 33])
def test_tyre_segment_counts(nseg):
    V, T, lab, kp = synth_bike(nseg=nseg)
    _check(V, T, lab, kp, seed=nseg)


def test_fat_tyres_no_chainring():
    V, T, lab, kp = synth_bike(nseg=20, tyre_r=0.06, chainring=False)
    _check(V, T, lab, kp, seed=3)


def test_fused_single_mesh_cm_off_origin():
    V, T, lab, kp = synth_bike(nseg=16)
    V, T, lab = fuse(V, T, lab)
    assert len(mesh.Soup(V, T).comps) == 1
    res, _, _ = _check(V, T, lab, kp, scale=100.0, offset=np.array([500.0, -300.0, 2000.0]), seed=5)
    assert res.record["wheels_from"] == "silhouette" and res.record["faces_cut"] > 0


def test_mm_units_rotated():
    V, T, lab, kp = synth_bike(nseg=33)
    _check(V, T, lab, kp, scale=1000.0, offset=np.array([-1e4, 2e3, 5e3]), seed=7)


def test_rider_is_removed():
    V, T, lab, kp = synth_bike(nseg=24, rider=True)
    res, _, _ = _check(V, T, lab, kp, seed=9)
    assert any("rider" in n for n in res.notes)


def test_refusals_name_the_failed_check():
    V, T, lab, _ = synth_bike(third_wheel=0.6)
    with pytest.raises(UserError, match="side by side on the rear axle"):
        pipeline.curate_arrays(transform(V, 1, 1.0, 0.0)[0], T)
    V, T, lab, _ = synth_bike(front_R=0.75, chainring=False)   # a penny-farthing: big front, small rear
    with pytest.raises(UserError, match="wheel sizes very unequal"):
        pipeline.curate_arrays(transform(V, 2, 1.0, 0.0)[0], T)
    V, T, lab, _ = synth_bike()
    # a frame without wheels: drop the tyres, rims, spokes and hubs (everything within R of an axle)
    cen = V[T].mean(1)
    near = np.minimum(np.hypot(cen[:, 0] + 0.45, cen[:, 1] - 0.35), np.hypot(cen[:, 0] - 0.62, cen[:, 1] - 0.35)) < 0.38
    Tf = T[~near]
    with pytest.raises(UserError, match="no wheels found"):
        pipeline.curate_arrays(V, Tf)
    # a flat icon: the whole bike squashed into its side plane
    Vf = V * [1, 1, 0.001]
    with pytest.raises(UserError, match="flat"):
        pipeline.curate_arrays(Vf, T)


def test_wheel_centres_given_by_the_annotator():
    """The wheel search is skipped: the annotator's centres (a few cm off) give the same curation."""
    V, T, lab, kp = synth_bike(nseg=12)
    Vm, q = transform(V, 4, 10.0, np.array([3.0, 1.0, -2.0]))
    fa = 10.0 * (kp["front_axle"] + [0.03, -0.02, 0.0]) @ q.T + [3.0, 1.0, -2.0]
    ra = 10.0 * (kp["rear_axle"] + [-0.02, 0.03, 0.0]) @ q.T + [3.0, 1.0, -2.0]
    res = pipeline.curate_arrays(Vm, T, 0.7, wheel_centres=(fa, ra))
    assert res.record["wheels_from"] == "given"
    assert res.problems == []
    for k in ("front_axle", "rear_axle", "crank_axle", "seat"):
        assert np.linalg.norm(res.keypoints[k] - kp[k]) < 0.03, k

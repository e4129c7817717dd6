"""Wheels: tyre, rim, hub, laced spokes (or cast spokes / solid PU), disc rotor, cassette."""
import numpy as np

from .meshkit import box, circle_profile, cylinder, extrude_annulus, revolve


def wheel(mb, centre, R, tyre_w, rim_depth, half_spacing, spokes=32, disc_side=0,
          cassette=None, kind="wire", tyre_segments=72):
    """Add one wheel whose tyre's outer radius is exactly R (lowest vertex at centre.y - R).

    disc_side: 0 none, -1 rider's left (canonical -Z), +1 right.  cassette: list of cog radii
    stacked inwards from the right dropout (bicycles), or None.
    """
    c = np.asarray(centre, float)
    tr = tyre_w / 2
    # tyre: a torus whose outermost ring sits at radius R; one vertex straight down
    prof = circle_profile(R - tr, 0.0, tr, n=14)
    mb.add(*revolve(prof, tyre_segments, c), "rubber")
    r_bead = R - 1.7 * tr
    rw = max(0.016, min(tyre_w * 0.75, 0.035)) if kind != "moto" else tyre_w * 0.85
    ri = r_bead - rim_depth
    rim_prof = [(r_bead + 0.002, -rw / 2), (r_bead + 0.002, rw / 2), (r_bead - 0.004, rw / 2),
                (ri + 0.003, rw * 0.22), (ri, 0.0), (ri + 0.003, -rw * 0.22), (r_bead - 0.004, -rw / 2)]
    mb.add(*revolve(rim_prof, tyre_segments, c), "rim", smooth=False)
    hs = half_spacing
    if kind == "solid":  # scooter: a polyurethane wheel with a solid core
        core = [(0.008, -tr * 0.9), (ri + 0.002, -tr * 0.9), (ri + 0.002, tr * 0.9), (0.008, tr * 0.9)]
        mb.add(*revolve(core, 32, c), "metal", smooth=False)
        mb.add(*cylinder(c + [0, 0, -hs], c + [0, 0, hs], 0.006, sides=10), "metal")
        return ri
    flange_r = 0.028 if kind == "wire" else 0.06
    fz = hs - 0.014
    hub = [(0.006, -hs), (0.013, -hs), (0.013, -fz - 0.002), (flange_r, -fz - 0.002), (flange_r, -fz + 0.002),
           (0.018, -fz + 0.002), (0.018, fz - 0.002), (flange_r, fz - 0.002), (flange_r, fz + 0.002),
           (0.013, fz + 0.002), (0.013, hs), (0.006, hs)]
    mb.add(*revolve(hub, 24, c), "metal")
    # axle rod through the dropouts: the axle keypoint lies inside it
    mb.add(*cylinder(c + [0, 0, -hs - 0.006], c + [0, 0, hs + 0.006], 0.0055, sides=10), "metal")
    if kind == "wire":
        _spokes(mb, c, spokes, flange_r - 0.004, fz, ri + 0.002)
    else:  # motorcycle cast wheel: five flat Y-spokes
        for k in range(5):
            a = np.radians(72 * k - 90)
            d = np.array([np.cos(a), np.sin(a), 0.0])
            mid = c + d * (flange_r + ri) / 2
            rot = np.column_stack([d, np.cross([0, 0, 1.0], d), [0, 0, 1.0]])
            mb.add(*box(mid, ((ri - flange_r) + 0.02, 0.028, 0.03), rot), "rim", smooth=False)
    if disc_side:
        zr = disc_side * (hs - 0.01)
        rr = 0.08 if kind == "wire" else 0.15
        mb.add(*_ring(c, rr - (0.014 if kind == "wire" else 0.035), rr, zr, 0.002, 40), "metal", smooth=False)
        for k in range(5):  # rotor spider
            a = np.radians(72 * k + 18)
            d = np.array([np.cos(a), np.sin(a), 0.0])
            p0, p1 = c + d * 0.02 + [0, 0, zr], c + d * (rr - 0.01) + [0, 0, zr]
            mb.add(*cylinder(p0, p1, 0.003, sides=4), "metal", smooth=False)
    if cassette:
        z = hs - 0.008
        for rc in cassette:
            mb.add(*_ring(c, 0.016, rc, z, 0.0018, 24), "metal", smooth=False)
            z -= 0.0045 if len(cassette) > 1 else 0.0
    return ri


def _ring(c, r_in, r_out, z, thick, n):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    circ = np.stack([np.cos(a), np.sin(a)], 1)
    return extrude_annulus(circ * r_out, circ * r_in, z - thick / 2, z + thick / 2, centre=c)


def _spokes(mb, c, n, r_hub, fz, r_rim):
    """n spokes, half per flange, laced radially (<= 24) or crossing 2-4 times."""
    cross = 0 if n <= 24 else (2 if n <= 28 else (3 if n <= 36 else 4))
    per = n // 2
    for side in (-1, 1):
        for k in range(per):
            a_hub = 2 * np.pi * k / per + (np.pi / per if side > 0 else 0.0)
            d = 1 if k % 2 == 0 else -1
            a_rim = a_hub + d * cross * 4 * np.pi / n
            p0 = c + [r_hub * np.cos(a_hub), r_hub * np.sin(a_hub), side * fz]
            p1 = c + [r_rim * np.cos(a_rim), r_rim * np.sin(a_rim), side * 0.002]
            mb.add(*cylinder(p0, p1, 0.0011, sides=4, caps=False), "metal", smooth=False)


def fender(mb, centre, R, width, start_deg, stop_deg, material="paint"):
    """A mudguard arc above the tyre: open U profile revolved over [start, stop] degrees."""
    w = width / 2
    prof = [(R + 0.008, -w), (R + 0.017, -0.6 * w), (R + 0.021, 0.0), (R + 0.017, 0.6 * w), (R + 0.008, w)]
    mb.add(*revolve(prof, 40, centre, np.radians(start_deg), np.radians(stop_deg), closed_profile=False),
           material)


def chainring(mb, centre, teeth, z, material="metal"):
    """A toothed chainring (alternating tooth tip / root radii), 4 mm thick."""
    r = teeth * 0.0127 / (2 * np.pi)  # 1/2-inch chain pitch
    m = 2 * teeth
    a = np.linspace(0, 2 * np.pi, m, endpoint=False)
    rad = np.where(np.arange(m) % 2 == 0, r + 0.004, r - 0.002)
    outer = np.stack([np.cos(a) * rad, np.sin(a) * rad], 1)
    inner = np.stack([np.cos(a), np.sin(a)], 1) * (r - 0.013)
    mb.add(*extrude_annulus(outer, inner, z - 0.002, z + 0.002, centre=centre), material, smooth=False)
    return r


__all__ = ["wheel", "fender", "chainring"]

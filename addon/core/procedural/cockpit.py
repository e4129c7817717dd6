"""The bicycle's steering part: fork with its steerer tube, front wheel, stem, handlebar, grips."""
import numpy as np

from .meshkit import MeshBuilder, bezier, box, catmull_rom, cylinder, frame_from_x, tube
from .wheels import fender, wheel

Z = np.array([0.0, 0.0, 1.0])
MIRROR = np.array([1.0, 1.0, -1.0])


def bar_curve(L):
    """Dense centreline of the whole bar, left end -> right end (canonical)."""
    right = catmull_rom(L["bar_path"], 8) if len(L["bar_path"]) > 2 else np.asarray(L["bar_path"])
    left = (right * MIRROR)[::-1]
    return np.vstack([left[:-1], right])


def end_segment(curve, length):
    """The last `length` metres of a polyline (from the end backwards), as a polyline."""
    seg = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    acc = np.concatenate([[0], np.cumsum(seg[::-1])])  # distance from the end
    rev = curve[::-1]
    keep = acc < length
    pts = list(rev[keep])
    i = int(keep.sum())
    if i < len(rev):
        t = (length - acc[i - 1]) / (acc[i] - acc[i - 1])
        pts.append(rev[i - 1] + t * (rev[i] - rev[i - 1]))
    return np.array(pts[::-1])


def point_from_end(curve, dist):
    return end_segment(curve, dist)[0]


def build_steering(s, L):
    mb = MeshBuilder()
    u, n = L["u"], L["n"]
    hb, ht, crown, fa = L["head_bottom"], L["head_top"], L["crown"], L["front_axle"]
    R, tw = L["R"], s["tyre_width_m"]
    fhs = L["front_half_spacing"]
    comp = "dark" if s["accent_dark"] else "metal"
    paint = "paint"
    # steerer tube on the steering axis, crown to stem top (both steering keypoints inside)
    mb.add(*cylinder(crown - 0.01 * u, L["steerer_top"], 0.0143, sides=16), comp)
    mb.add(*cylinder(hb - LOWER(u), hb, 0.024, sides=20), "dark")   # lower headset cup
    mb.add(*cylinder(ht, ht + 0.008 * u, 0.024, sides=20), "dark")   # upper headset cup
    if s["spacer_m"] > 0.009:
        mb.add(*cylinder(ht + 0.008 * u, ht + s["spacer_m"] * u, 0.0175, sides=16), "dark")
    # stem: steerer clamp, body, bar clamp
    sc, bc = L["stem_clamp"], L["bar_clamp"]
    mb.add(*cylinder(sc - 0.02 * u, sc + 0.02 * u, 0.02, sides=16), comp)
    mb.add(*tube([sc, bc], 0.0155, sides=14), comp)
    mb.add(*cylinder(bc - 0.027 * Z, bc + 0.027 * Z, 0.0195, sides=16), comp)
    # handlebar
    curve = bar_curve(L)
    r_bar = 0.011 if s["handlebar"] == "bmx" else 0.0122
    bar_mat = "tape" if s["handlebar"] == "drop" else comp
    mb.add(*tube(curve, r_bar, sides=12), bar_mat)
    if s["handlebar"] == "bmx":  # BMX crossbar between the uprights
        p = L["bar_path"]
        a, b = p[1] + 0.55 * (p[2] - p[1]), p[1] + 0.55 * (p[2] - p[1])
        mb.add(*tube([a * MIRROR, b], 0.0095, sides=10), bar_mat)
    if s["handlebar"] == "drop":
        for m in (MIRROR, np.ones(3)):  # brake hoods around the hand keypoint
            hand = L["grip_centre"] * m
            rot = frame_from_x([1.0, 0.35, 0.0])
            mb.add(*box(hand + np.array([0.012, 0.014, 0]), (0.075, 0.038, 0.028), rot), "dark", smooth=False)
            lever = [hand + np.array([0.04, 0.0, 0]), hand + np.array([0.05, -0.06, 0]), hand + np.array([0.03, -0.09, 0])]
            mb.add(*tube(lever, 0.005, sides=6), "metal")
    else:
        grip = end_segment(curve, 0.13)
        for m in (MIRROR, np.ones(3)):
            g = grip * m
            mb.add(*tube(g, 0.0165, sides=14), "grip")
            inner = g[0]
            mb.add(*tube([inner + np.array([0.0, 0.005, 0]), inner + np.array([0.05, 0.008, 0.01 * np.sign(inner[2])]),
                          inner + np.array([0.09, -0.015, 0.05 * np.sign(inner[2])])], 0.0045, sides=6), "metal")
    # fork
    if s["fork_type"] == "suspension":
        _suspension_fork(mb, s, L, comp)
    else:
        zc = tw / 2 + 0.014
        a2c = L["fork_a2c"]
        mb.add(*box(crown - 0.015 * u, (0.04, 0.034, 2 * zc + 0.03), np.column_stack([n, u, Z])), paint,
               smooth=False)
        for sg in (-1, 1):
            start = crown - 0.02 * u + sg * zc * Z
            end = fa + sg * (fhs - 0.004) * Z
            ctrl = crown - 0.02 * u - 0.72 * a2c * u + sg * (0.5 * (zc + fhs)) * Z
            blade = bezier(start, ctrl, end, n=12)
            mb.add(*tube(blade, np.linspace(0.0135, 0.0075, 12), sides=12), paint)
            mb.add(*box(fa + sg * (fhs - 0.002) * Z + 0.006 * u, (0.03, 0.03, 0.006)), paint, smooth=False)
    with mb.tagged("front_wheel"):  # its own mesh when the bike has wheel sub-parts (build.py)
        wheel(mb, fa, R, tw, s["rim_depth_m"], fhs, spokes=s["spokes"], disc_side=-1 if s["disc_brakes"] else 0)
    if s["fenders"]:
        fender(mb, fa, R, tw + 0.02, 20, 190)
    return mb


def LOWER(u):
    return 0.012 * u


def _suspension_fork(mb, s, L, comp):
    u, n = L["u"], L["n"]
    fa, crown = L["front_axle"], L["crown"]
    fhs = L["front_half_spacing"]
    a2c = L["fork_a2c"]
    legs_top = a2c - 0.005
    off = np.dot(fa - crown, n)   # the crown carries the offset: legs parallel to the axis
    for sg in (-1, 1):
        base = fa + sg * fhs * Z
        mb.add(*cylinder(base - 0.02 * u, base + 0.29 * u, 0.021, sides=16), "dark")   # lowers
        mb.add(*cylinder(base + 0.25 * u, base + legs_top * u, 0.0165, sides=16), "stanchion")
        mb.add(*box(base + 0.004 * u, (0.035, 0.035, 0.012), np.column_stack([n, u, Z])), "dark", smooth=False)
    # arch over the tyre joining the lowers
    arch = bezier(fa + 0.24 * u - fhs * Z, fa + 0.3 * u + 0.035 * n, fa + 0.24 * u + fhs * Z, n=12)
    mb.add(*tube(arch, 0.011, sides=10), "dark")
    # crown: spans from the steerer to both stanchions
    cc = crown - 0.018 * u + 0.5 * off * n
    mb.add(*box(cc, (abs(off) + 0.05, 0.036, 2 * fhs + 0.045), np.column_stack([n, u, Z])), "dark", smooth=False)

"""The bicycle's frame part: tubes, BB shell, dropouts, seat post, saddle, rear wheel, chain."""
import numpy as np

from .meshkit import MeshBuilder, bezier, box, catmull_rom, cylinder, loft, tube
from .wheels import fender, wheel

Z = np.array([0.0, 0.0, 1.0])


def saddle(mb, top_centre, length, width, nose_width=0.035, thick=0.05, material="saddle", k=16, m=16):
    """A lofted saddle: rounded wide rear, tapering nose pointing +X; top-centre at top_centre."""
    c = np.asarray(top_centre, float)
    rings = []
    for i in range(k):
        t = i / (k - 1)
        tail = np.sin(0.5 * np.pi * min(t / 0.14, 1.0)) ** 0.6
        taper = np.clip((t - 0.35) / 0.6, 0, 1)
        taper = taper * taper * (3 - 2 * taper)
        w = max(0.012, (width - (width - nose_width) * taper) * tail)
        nose_round = np.sin(0.5 * np.pi * min((1 - t) / 0.06, 1.0)) ** 0.5
        w = max(0.01, w * nose_round)
        th = thick * (1 - 0.35 * t) * max(0.25, tail * nose_round)
        ytop = c[1] + 0.006 * np.cos(np.pi * t)   # rear slightly raised, nose slightly lower
        ytop -= 0.006 * np.cos(np.pi * 0.5)       # (zero at mid-length: the keypoint's place)
        x = c[0] + (t - 0.5) * length
        a = np.linspace(0, 2 * np.pi, m, endpoint=False)
        s = np.sin(a)
        y = ytop - 0.7 * th + np.where(s > 0, 0.7 * th, 0.3 * th) * s
        rings.append(np.stack([np.full(m, x), y, 0.5 * w * np.cos(a)], 1))
    mb.add(*loft(rings), material)


def cog_radii(s):
    """Radii (m) of the rear cogs, smallest outboard: a cassette or one single-speed cog."""
    if s["derailleur"]:
        n = int(s["cogs"])
        return list(np.linspace(0.025 + 0.012 * (n >= 12), 0.05 if s["style"] != "mountain" else 0.085, n))
    return [0.036]


def build_frame(s, L):
    """MeshBuilder of the frame part (canonical)."""
    mb = MeshBuilder()
    ts = s["tube_scale"]
    bb, rear, u, sd = L["bb"], L["rear_axle"], L["u"], L["sdir"]
    hb, ht = L["head_bottom"], L["head_top"]
    cl = L["seat_cluster"]
    R, tw = L["R"], s["tyre_width_m"]
    hs = L["rear_half_spacing"]
    paint = "paint"
    r_head = 0.021 * min(ts, 1.2)
    # head tube, slightly longer than the headset so both steering keypoints sit inside
    mb.add(*cylinder(hb - 0.004 * u, ht + 0.004 * u, r_head, sides=20), paint)
    r_tt, r_dt, r_st = 0.0135 * ts, 0.0175 * ts, 0.0145 * ts
    ftype = s["frame_type"]
    if ftype in ("diamond", "bmx"):
        mb.add(*tube([L["tt_front"], cl + 0.01 * sd], r_tt, sides=16), paint)
        mb.add(*tube([hb + 0.035 * u, bb], r_dt, sides=16), paint)
    elif ftype == "step_through":
        # a low, swooping main tube from the head tube to just above the BB, plus a down tube
        p0 = hb + 0.55 * (ht - hb)
        p3 = bb + 0.16 * sd
        path = bezier(p0, p0 + np.array([-0.12, -0.18, 0]), p3 + np.array([0.2, 0.02, 0]), p3, n=16)
        mb.add(*tube(path, r_dt * 1.05, sides=16), paint)
        mb.add(*tube([hb + 0.03 * u, bb], r_dt * 0.9, sides=16), paint)
    else:  # cruiser: an arched top tube and a curved down tube (twin-tube balloon-bike look)
        p0, p3 = L["tt_front"], cl + 0.01 * sd
        path = bezier(p0, p0 + np.array([-0.12, -0.12, 0]), p3 + np.array([0.18, -0.15, 0]), p3, n=16)
        mb.add(*tube(path, r_tt * 1.1, sides=16), paint)
        q0 = hb + 0.02 * u
        path = bezier(q0, q0 + np.array([-0.08, -0.2, 0]), bb + np.array([0.2, 0.05, 0]), bb, n=16)
        mb.add(*tube(path, r_dt, sides=16), paint)
        path = bezier(hb + 0.45 * (ht - hb), hb + np.array([-0.1, -0.08, 0]), cl - 0.15 * sd + np.array([0.15, 0, 0]),
                      cl - 0.2 * sd, n=14)
        mb.add(*tube(path, r_tt * 0.85, sides=12), paint)
    mb.add(*tube([bb - 0.012 * sd, cl + 0.025 * sd], r_st, sides=16), paint)
    # bottom-bracket shell along Z: the crank axle keypoint is inside it
    mb.add(*cylinder(bb - 0.035 * Z, bb + 0.035 * Z, 0.021, sides=20), paint)
    zc = tw / 2 + 0.012
    for sg in (-1, 1):
        # chain stays: narrow at the BB, around the tyre, out to the dropout
        mid = bb + 0.55 * (rear - bb)
        cs = catmull_rom([bb + np.array([-0.02, 0, sg * 0.03]), mid + sg * zc * Z,
                          rear + np.array([0.012, 0, sg * (hs - 0.006)])], 6)
        mb.add(*tube(cs, np.linspace(0.0105, 0.0065, len(cs)) * ts, sides=10), paint)
        top = cl - 0.02 * sd
        mid = top + 0.55 * (rear - top)
        ss = catmull_rom([top + sg * 0.018 * Z, mid + sg * (zc + 0.004) * Z,
                          rear + np.array([0.006, 0.01, sg * (hs - 0.006)])], 6)
        mb.add(*tube(ss, np.linspace(0.008, 0.006, len(ss)) * ts, sides=10), paint)
        mb.add(*box(rear + np.array([0.004, 0.004, sg * (hs - 0.004)]), (0.045, 0.035, 0.006)), paint, smooth=False)
    comp = "dark" if s["accent_dark"] else "metal"
    # seat post (27.2 mm), clamp collar, saddle
    mb.add(*cylinder(cl - 0.03 * sd, L["post_top"], 0.0136, sides=16), comp)
    mb.add(*cylinder(cl + 0.015 * sd, cl + 0.04 * sd, 0.0175, sides=16), comp)
    mb.add(*box(L["post_top"] + np.array([0.0, 0.012, 0]), (0.055, 0.022, 0.03)), comp, smooth=False)
    sl, sw = s["saddle_length_m"], s["saddle_width_m"]
    if s["style"] == "cruiser":
        for sg in (-1, 1):  # coil springs under a sprung saddle
            base = L["saddle_top"] + np.array([-0.07, -0.09, sg * 0.05])
            mb.add(*cylinder(base, base + np.array([0, 0.06, 0]), 0.012, sides=10), "metal")
    saddle(mb, L["saddle_top"], sl, sw, thick=0.05 if s["style"] != "cruiser" else 0.07)
    # rear wheel with cassette or single cog
    cogs = cog_radii(s)
    with mb.tagged("rear_wheel"):  # its own mesh when the bike has wheel sub-parts (build.py)
        wheel(mb, rear, R, tw, s["rim_depth_m"], hs, spokes=s["spokes"], disc_side=-1 if s["disc_brakes"] else 0,
              cassette=cogs)
    if s["fenders"]:
        fender(mb, rear, R, tw + 0.02, 60, 215)
    _chain(mb, s, L, cogs)
    return mb


def _chain(mb, s, L, cogs):
    """Chain loop: around the front of the chainring and the back of the cog (on the frame part:
    it does not turn with the crank arms, and its shape is unchanged when they turn)."""
    z = L["chainline"]
    teeth = s["chainring_teeth"]
    r_ring = teeth * 0.0127 / (2 * np.pi)
    r_cog = max(cogs) * 0.55 + min(cogs) * 0.45 if len(cogs) > 1 else cogs[0]
    bb = L["bb"] + z * Z
    rear = L["rear_axle"] + z * Z
    a1 = np.linspace(np.pi / 2, -np.pi / 2, 14)
    ring = bb + np.stack([np.cos(a1), np.sin(a1), 0 * a1], 1) * r_ring
    a2 = np.linspace(-np.pi / 2, -3 * np.pi / 2, 10)
    cog = rear + np.stack([np.cos(a2), np.sin(a2), 0 * a2], 1) * r_cog
    path = np.vstack([ring, cog])
    mb.add(*tube(path, 0.004, sides=4, closed=True, squash=0.5, up=Z), "dark", smooth=False)
    if s["derailleur"]:
        rear0 = L["rear_axle"]
        cage_top = rear0 + np.array([0.0, -0.055, z + 0.004])
        cage_bot = rear0 + np.array([0.03, -0.11, z + 0.004])
        for p in (cage_top, cage_bot):
            mb.add(*cylinder(p - 0.003 * Z, p + 0.003 * Z, 0.017, sides=14), "dark")
        mb.add(*tube([rear0 + np.array([-0.005, -0.01, L["rear_half_spacing"] + 0.004]), cage_top + 0.01 * Z,
                      cage_bot + 0.01 * Z], 0.008, sides=8), "dark")

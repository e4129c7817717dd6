"""Rideables without pedals: a kick scooter and a motorcycle (frame + steering parts only).

Their keypoints keep docs/contract.md's names (layout.keypoints documents the stand-ins: the scooter's
deck centre / feet, the motorcycle's footpeg axis and footpegs for crank_axle / pedal_*).
"""
import numpy as np

from .meshkit import MeshBuilder, bezier, box, cylinder, ellipsoid, frame_from_x, tube
from .tubes import saddle
from .cockpit import bar_curve, end_segment
from .wheels import fender, wheel

Z = np.array([0.0, 0.0, 1.0])
MIRROR = np.array([1.0, 1.0, -1.0])


def scooter_frame(s, L):
    mb = MeshBuilder()
    dl, dw = s["deck_length_m"], s["deck_width_m"]
    top, th = L["deck_top"], L["deck_thick"]
    rear, u = L["rear_axle"], L["u"]
    R, tw = L["R"], s["tyre_width_m"]
    mb.add(*box([0, top - th / 2, 0], (dl, th, dw)), "paint", smooth=False)
    mb.add(*box([0, top - 0.001, 0], (dl - 0.02, 0.003, dw - 0.012)), "grip", smooth=False)  # grip tape
    for sg in (-1, 1):  # rear wheel plates
        mb.add(*tube([[-dl / 2 + 0.02, top - th / 2, sg * (tw / 2 + 0.008)], rear + sg * (tw / 2 + 0.008) * Z],
                     0.008, sides=8), "paint")
    mb.add(*cylinder(rear - (tw / 2 + 0.016) * Z, rear + (tw / 2 + 0.016) * Z, 0.0055, sides=10), "metal")
    wheel(mb, rear, R, tw, 0.01, tw / 2 + 0.012, kind="solid")
    fender(mb, rear, R, tw + 0.014, 60, 190, material="dark")
    # neck from the deck's front to the head tube
    hb, ht = L["head_bottom"], L["head_top"]
    neck = bezier([dl / 2 - 0.05, top - th / 2, 0], [dl / 2 + 0.05, top - 0.01, 0], hb - 0.01 * u, n=10)
    mb.add(*tube(neck, 0.02, sides=12), "paint")
    mb.add(*cylinder(hb - 0.006 * u, ht + 0.006 * u, 0.022, sides=16), "paint")
    return mb


def scooter_steering(s, L):
    mb = MeshBuilder()
    u, fa = L["u"], L["front_axle"]
    R, tw = L["R"], s["tyre_width_m"]
    crown, bc = L["crown"], L["bar_clamp"]
    mb.add(*cylinder(crown - 0.005 * u, bc + 0.02 * u, 0.016, sides=14), "metal")
    mb.add(*cylinder(L["head_top"] + 0.12 * u, L["head_top"] + 0.17 * u, 0.021, sides=14), "dark")  # clamp
    for sg in (-1, 1):
        mb.add(*tube([crown + sg * (tw / 2 + 0.01) * Z, fa + sg * (tw / 2 + 0.01) * Z], 0.008, sides=8), "metal")
    mb.add(*box(crown, (0.03, 0.02, tw + 0.04)), "metal", smooth=False)
    mb.add(*cylinder(fa - (tw / 2 + 0.016) * Z, fa + (tw / 2 + 0.016) * Z, 0.0055, sides=10), "metal")
    wheel(mb, fa, R, tw, 0.01, tw / 2 + 0.012, kind="solid")
    curve = bar_curve(L)
    mb.add(*tube(curve, 0.0115, sides=12), "metal")
    grip = end_segment(curve, 0.12)
    for m in (MIRROR, np.ones(3)):
        mb.add(*tube(grip * m, 0.0165, sides=12), "grip")
    return mb


def motorcycle_frame(s, L):
    mb = MeshBuilder()
    u = L["u"]
    hb, ht = L["head_bottom"], L["head_top"]
    rear, R, tw = L["rear_axle"], L["R"], s["tyre_width_m"]
    bb = L["bb"]
    # engine: round crankcase covers (contain the footpeg-axis keypoint), gearbox, finned
    # cylinder leaning forward, head
    mb.add(*cylinder([0.12, 0.42, -0.15], [0.12, 0.42, 0.15], 0.15, sides=28), "dark")
    mb.add(*cylinder([0.12, 0.42, -0.16], [0.12, 0.42, 0.16], 0.09, sides=20), "metal")
    mb.add(*box([-0.02, 0.36, 0], (0.2, 0.17, 0.24)), "dark", smooth=False)
    lean = np.radians(22)
    ax = np.array([np.sin(lean), np.cos(lean), 0.0])
    base = np.array([0.18, 0.52, 0.0])
    for i in range(7):  # cooling fins
        p = base + ax * (0.03 + 0.028 * i)
        mb.add(*cylinder(p - 0.004 * ax, p + 0.004 * ax, 0.085, sides=20), "metal")
    mb.add(*cylinder(base, base + 0.22 * ax, 0.06, sides=16), "dark")
    mb.add(*box(base + 0.25 * ax, (0.15, 0.07, 0.2), frame_from_x([ax[1], -ax[0], 0], ax)), "metal",
           smooth=False)
    # frame tubes: twin spars head -> swingarm pivot, and a cradle under the engine
    piv = L["swingarm_pivot"]
    for sg in (-1, 1):
        spar = bezier(ht - 0.03 * u + sg * 0.03 * Z, [0.3, 0.86, sg * 0.12], piv + sg * 0.12 * Z, n=14)
        mb.add(*tube(spar, 0.022, sides=12), "paint")
        cradle = bezier(hb + sg * 0.03 * Z, [0.55, 0.22, sg * 0.1], piv + np.array([-0.05, -0.15, sg * 0.12]), n=14)
        mb.add(*tube(cradle, 0.017, sides=10), "paint")
        sub = [piv + np.array([-0.02, 0.3, sg * 0.11]), [-0.62, 0.74, sg * 0.08]]
        mb.add(*tube(sub, 0.013, sides=8), "paint")
        arm = [piv + sg * 0.12 * Z, rear + sg * (tw / 2 + 0.03) * Z]
        mb.add(*tube(arm, 0.022, sides=10, squash=1.6), "dark")
        # rear shocks
        mb.add(*cylinder(rear + np.array([0.05, 0.03, sg * (tw / 2 + 0.04)]), [-0.38, 0.74, sg * (tw / 2 + 0.04)],
                         0.018, sides=10), "stanchion")
        # footpegs: the pedal_* keypoints are their centres
        peg = np.array([0, bb[1], 0])
        mb.add(*cylinder(peg + sg * 0.12 * Z, peg + sg * 0.225 * Z, 0.014, sides=10), "rubber")
        mb.add(*box(peg + np.array([-0.03, 0.02, sg * 0.13]), (0.08, 0.06, 0.012)), "metal", smooth=False)
    mb.add(*cylinder(hb - 0.012 * u, ht + 0.012 * u, 0.03, sides=16), "paint")
    # fuel tank, seat, tail
    tank_rot = frame_from_x([np.cos(np.radians(-8)), np.sin(np.radians(-8)), 0])
    mb.add(*ellipsoid([0.24, 0.9, 0], (0.27, 0.12, 0.17), tank_rot, seg=24, rings=12), "paint")
    saddle(mb, L["seat_top"], 0.56, 0.3, nose_width=0.2, thick=0.1, material="saddle")
    mb.add(*ellipsoid([-0.62, 0.82, 0], (0.2, 0.06, 0.1), frame_from_x([1, 0.25, 0]), seg=16, rings=8), "paint")
    mb.add(*box([-0.8, 0.85, 0], (0.03, 0.04, 0.1)), "taillight", smooth=False)
    # exhaust on the right: header from the cylinder head under the engine, then the muffler
    pipe = bezier([0.3, 0.7, 0.06], [0.55, 0.22, 0.16], [-0.15, 0.22, 0.19], n=16)
    mb.add(*tube(pipe, 0.022, sides=10), "metal")
    mb.add(*tube([[-0.15, 0.22, 0.19], [-0.3, 0.3, 0.2]], 0.024, sides=10), "metal")
    mb.add(*cylinder([-0.3, 0.3, 0.2], [-0.72, 0.48, 0.19], 0.055, sides=16), "metal")
    mb.add(*cylinder([-0.36, 0.52, -0.1], [-0.36, 0.52, 0.1], 0.03, sides=12), "dark")  # battery/airbox
    wheel(mb, rear, R, tw, 0.012, tw / 2 + 0.035, disc_side=1, kind="moto", tyre_segments=72)
    fender(mb, rear, R, tw + 0.03, 70, 150, material="dark")
    # drive chain and sprocket on the left
    mb.add(*cylinder(rear - (tw / 2 + 0.028) * Z, rear - (tw / 2 + 0.022) * Z, 0.1, sides=28), "metal")
    mb.add(*tube([piv + np.array([-0.02, 0.05, -0.1]), rear + np.array([0, 0.1, -0.125]), rear + np.array([0, -0.1, -0.125]),
                  piv + np.array([-0.02, -0.03, -0.1])], 0.006, sides=4, closed=True), "dark")
    return mb


def motorcycle_steering(s, L):
    mb = MeshBuilder()
    u, n = L["u"], L["n"]
    fa, ft = L["front_axle"], L["fork_top"]
    hb, ht = L["head_bottom"], L["head_top"]
    R, tw = L["R"], s["tyre_width_m"]
    zl = tw / 2 + 0.045
    rot = np.column_stack([n, u, Z])
    for sg in (-1, 1):
        base = fa + sg * zl * Z
        mb.add(*cylinder(base - 0.03 * u, base + 0.38 * u, 0.032, sides=16), "dark")
        mb.add(*cylinder(base + 0.3 * u, base + 0.9 * u, 0.025, sides=16), "stanchion")
    for p in (ft, ft + 0.17 * u):  # triple clamps
        mb.add(*box(p - 0.5 * np.dot(p - hb, n) * n, (0.08, 0.035, 2 * zl + 0.08), rot), "metal", smooth=False)
    mb.add(*cylinder(hb - 0.02 * u, ht + 0.03 * u, 0.02, sides=14), "metal")   # steering stem
    bc = L["bar_clamp"]
    for sg in (-1, 1):
        mb.add(*cylinder(ht + 0.03 * u + sg * 0.04 * Z, bc + sg * 0.04 * Z, 0.014, sides=10), "metal")
    curve = bar_curve(L)
    mb.add(*tube(curve, 0.0115, sides=12), "metal")
    grip = end_segment(curve, 0.13)
    for m in (MIRROR, np.ones(3)):
        mb.add(*tube(grip * m, 0.018, sides=12), "grip")
    # headlight and instrument
    lamp = ht + 0.02 * u + 0.16 * n
    mb.add(*cylinder(lamp - 0.07 * n, lamp + 0.03 * n, 0.085, sides=24), "dark")
    mb.add(*cylinder(lamp + 0.03 * n, lamp + 0.04 * n, 0.08, sides=24), "lamp")
    mb.add(*cylinder(ht + 0.1 * u, ht + 0.12 * u, 0.05, sides=16), "dark")
    wheel(mb, fa, R, tw, 0.012, tw / 2 + 0.03, disc_side=-1, kind="moto", tyre_segments=72)
    mb.add(*cylinder(fa + (tw / 2 + 0.02) * Z, fa + (tw / 2 + 0.022) * Z, 0.15, sides=32), "metal")  # 2nd disc
    fender(mb, fa, R, tw + 0.03, 20, 150, material="paint")
    return mb

"""The bicycle's crank part: spindle, crank arms, chainring(s) with spider, pedals.

Canonical crank pose: right arm (+Z side) pointing forward (+X), left arm backward.
"""
import numpy as np

from .meshkit import MeshBuilder, box, cylinder, tube
from .wheels import chainring

Z = np.array([0.0, 0.0, 1.0])


def build_crank(s, L):
    mb = MeshBuilder()
    bb = L["bb"]
    q = L["crank_q"]
    cl = s["crank_length_m"]
    comp = "dark" if s["accent_dark"] else "metal"
    mb.add(*cylinder(bb - (q + 0.008) * Z, bb + (q + 0.008) * Z, 0.0125, sides=16), "metal")
    for sg in (1, -1):  # +1: right arm forward; -1: left arm backward
        root = bb + sg * q * Z
        tip = bb + np.array([sg * cl, 0, sg * q])
        arm = np.linspace(root, tip, 6)
        mb.add(*tube(arm, np.linspace(0.017, 0.011, 6), sides=12, squash=0.55, up=Z), comp)
        mb.add(*cylinder(root - sg * 0.006 * Z, root + sg * 0.006 * Z, 0.019, sides=16), comp)
        # pedal spindle and platform body (the pedal keypoint is the body's centre)
        pc = L["pedal_right"] if sg > 0 else L["pedal_left"]
        mb.add(*cylinder(tip, pc + sg * 0.045 * Z, 0.0065, sides=8), "metal")
        with mb.tagged("pedal_right" if sg > 0 else "pedal_left"):  # the level pedal sub-part (build.py)
            if s["style"] in ("road", "gravel"):
                mb.add(*box(pc, (0.085, 0.02, 0.07)), "dark", smooth=False)
            else:
                mb.add(*box(pc, (0.10, 0.022, 0.095)), "dark" if s["style"] != "city" else "metal", smooth=False)
                for dx in (-0.045, 0.045):  # platform cage rails
                    mb.add(*box(pc + np.array([dx, 0, 0]), (0.008, 0.03, 0.095)), "metal", smooth=False)
    z = L["chainline"]
    r = chainring(mb, bb, int(s["chainring_teeth"]), z)
    if s["style"] == "road":  # double: a 34-39T inner ring
        chainring(mb, bb, int(0.72 * s["chainring_teeth"]), z - 0.006)
    # spider arms from the right crank root to the ring
    n_arms = 4 if s["style"] in ("road", "gravel", "mountain") else 5
    for k in range(n_arms):
        a = 2 * np.pi * k / n_arms + np.pi / n_arms
        d = np.array([np.cos(a), np.sin(a), 0.0])
        mb.add(*tube([bb + 0.012 * d + (z + 0.004) * Z, bb + (r - 0.008) * d + (z + 0.003) * Z], 0.006,
                     sides=6, squash=0.6, up=Z), comp)
    return mb

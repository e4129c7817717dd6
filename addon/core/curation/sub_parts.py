"""Which faces of a bike's parts are its wheels and pedal bodies (numpy, no bpy): the sub-parts
of docs/contract.md "Sub-parts", for a bike that was split into frame / steering / crank only
(a curated model, a procedural bike made with --no-sub-parts).

Rigid pieces are whole connected components (vertices welded by position, mesh.weld):
- a wheel piece lies inside the wheel's disc about its axle (radius: the axle height, the tyre
  touching the ground, + 4 mm; within 12 cm of the wheel plane) and either goes round the axle
  (a tyre, rim, hub, axle, rotor ring or cog: no gap wider than 40 degrees between the angles of
  its vertices about the axle, a 10-sided axle rod has 36; centred on it within R / 10)
  or is a thin rod from the hub to the rim (a spoke) or to a disc rotor (its spider arm; less
  than 10 cm from the axle);
- a pedal piece lies within 8 cm of its pedal keypoint, around it (its centre within 5 cm across
  Z: the body, its cage rails) and is not a thin rod (the spindle, fixed in the crank arm).
Everything else stays on its part: the fork and its dropouts, mudguards, calipers, the chain, a
pedal fused with its crank arm (one component; then the bike simply has no pedal sub-part).
"""
import numpy as np

from .mesh import connected_components, weld

# sub-part -> (the part it is cut from, the keypoint it is found around)
SOURCES = {"front_wheel": ("steering", "front_axle"), "rear_wheel": ("frame", "rear_axle"),
           "pedal_left": ("crank", "pedal_left"), "pedal_right": ("crank", "pedal_right")}
MAX_GAP_DEG = 40.0
DISC_MARGIN_M, HALF_WIDTH_M = 0.004, 0.12
PEDAL_REACH_M, PEDAL_CENTRE_M = 0.08, 0.05


def _components(V, T):
    inv, _ = weld(V)
    comp_v = connected_components(int(inv.max()) + 1 if len(inv) else 0, inv[T])
    return comp_v[inv[T[:, 0]]]  # component per triangle


def wheel_triangles(V, T, axle):
    """Bool per triangle of (V canonical (n, 3), T (m, 3)): on the wheel about `axle`."""
    axle = np.asarray(axle, float)
    R = float(axle[1])
    d = V - axle
    r = np.hypot(d[:, 0], d[:, 1])
    ang = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    comp = _components(V, T)
    out = np.zeros(len(T), bool)
    for c in np.unique(comp):
        tri = comp == c
        vi = np.unique(T[tri])
        if r[vi].max() > R + DISC_MARGIN_M or np.abs(d[vi, 2]).max() > HALF_WIDTH_M:
            continue
        a = np.sort(ang[vi][r[vi] > 0.002])
        # centred (a real model's tyre sits 1-2 cm off the fitted axle); a suspension fork's
        # lower leg, which also goes round the axle, is centred 10+ cm away along the fork
        centred = np.hypot(*d[vi, :2].mean(0)) < 0.1 * R
        ring = centred and len(a) > 2 and np.diff(np.r_[a, a[0] + 360.0]).max() <= MAX_GAP_DEG
        # a spoke (hub to rim) or a disc rotor's spider arm (hub to rotor): a thin rod from the hub
        sd = np.sqrt(np.maximum(np.linalg.eigvalsh(np.cov(V[vi].T)), 0.0)) if len(vi) > 3 else np.zeros(3)
        thin = sd[1] < 0.004
        spoke = thin and r[vi].min() < 0.25 * R and (r[vi].max() > 0.6 * R or r[vi].max() < 0.1)
        out[tri] = ring or spoke
    return out


def pedal_triangles(V, T, pedal):
    """Bool per triangle: on the pedal body around the keypoint `pedal`."""
    pedal = np.asarray(pedal, float)
    comp = _components(V, T)
    out = np.zeros(len(T), bool)
    for c in np.unique(comp):
        tri = comp == c
        P = V[np.unique(T[tri])]
        if np.linalg.norm(P - pedal, axis=1).max() > PEDAL_REACH_M:
            continue
        sd = np.sqrt(np.maximum(np.linalg.eigvalsh(np.cov(P.T)), 0.0)) if len(P) > 3 else np.zeros(3)
        spindle = sd[1] < 0.006  # a thin rod: the spindle, fixed in the crank arm
        out[tri] = np.linalg.norm(P.mean(0)[:2] - pedal[:2]) < PEDAL_CENTRE_M and not spindle
    return out


def sub_part_triangles(part, V, T, kp):
    """{sub-part: bool per triangle} for the faces of `part` (canonical V, T) that are sub-parts;
    only non-empty ones."""
    V, T = np.asarray(V, float), np.asarray(T, np.int64).reshape(-1, 3)
    out = {}
    for sub, (main, key) in SOURCES.items():
        if main != part or key not in kp:
            continue
        sel = wheel_triangles(V, T, kp[key]) if sub.endswith("_wheel") else pedal_triangles(V, T, kp[key])
        if sel.any():
            out[sub] = sel
    return out

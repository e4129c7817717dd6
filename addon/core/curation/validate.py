"""Keypoint checks with messages that name the failing keypoint (numpy, no bpy).

validate(kp) -> list of problem strings, empty when the keypoints make a plausible bicycle in
docs/contract.md's canonical frame (X forward, Y up, Z right, ground Y = 0, crank axle on the Y axis).
"""
import numpy as np

from ..procedural.layout import KEYPOINT_NAMES


def validate(kp, has_crank=True, tol=0.02):
    probs = []
    for n in KEYPOINT_NAMES:
        if n not in kp or kp[n] is None:
            probs.append(f"{n}: missing")
        elif np.asarray(kp[n]).shape != (3,) or not np.all(np.isfinite(kp[n])):
            probs.append(f"{n}: not a finite 3D point")
    if probs:
        return probs
    k = {n: np.asarray(kp[n], float) for n in KEYPOINT_NAMES}
    # steering axis
    axis = k["steer_top"] - k["steer_bottom"]
    L = np.linalg.norm(axis)
    if L < 0.03:
        probs.append(f"steer_top: only {L * 100:.1f} cm from steer_bottom (steering axis degenerate)")
    else:
        a = axis / L
        if a[1] <= 0:
            probs.append("steer_top: below steer_bottom (steering axis points down)")
        else:
            ang = np.degrees(np.arctan2(a[1], -a[0]))
            if not 45 <= ang <= 90:
                probs.append(f"steer_top: steering axis at {ang:.0f} deg from the ground (expected 45-90, leaning back)")
        if abs(a[2]) > 0.1:
            probs.append("steer_top: steering axis not in the plane of symmetry (Z component)")
        # the front axle sits near the steering axis (fork offset is a few cm)
        d = k["front_axle"] - k["steer_bottom"]
        off = np.linalg.norm(d - (d @ a) * a)
        if off > 0.15:
            probs.append(f"front_axle: {off * 100:.0f} cm from the steering axis (fork offset is a few cm)")
    # symmetry plane
    for n in ("seat", "steer_top", "steer_bottom", "crank_axle", "front_axle", "rear_axle", "ground"):
        if abs(k[n][2]) > tol:
            probs.append(f"{n}: Z = {k[n][2] * 100:.1f} cm, expected on the plane of symmetry (Z = 0)")
    if abs(k["crank_axle"][0]) > tol:
        probs.append(f"crank_axle: X = {k['crank_axle'][0] * 100:.1f} cm, expected on the Y axis (X = 0)")
    if abs(k["ground"][1]) > tol:
        probs.append(f"ground: Y = {k['ground'][1] * 100:.1f} cm, expected on the ground (Y = 0)")
    # wheels
    if k["front_axle"][0] <= k["rear_axle"][0]:
        probs.append("front_axle: not in front of rear_axle (X forward)")
    for n in ("front_axle", "rear_axle"):
        if k[n][1] <= 0.02:
            probs.append(f"{n}: at or below the ground")
    if not k["rear_axle"][0] < k["crank_axle"][0] < k["front_axle"][0]:
        probs.append("crank_axle: not between the wheel axles")
    # a saddle is well above the crank; a kick scooter's standing place is on its deck
    if k["seat"][1] < k["crank_axle"][1] + (0.15 if has_crank else 0.0):
        probs.append("seat: not above crank_axle")
    # left/right pairs
    for left, right in (("handle_left", "handle_right"), ("pedal_left", "pedal_right")):
        if not k[left][2] < 0:
            probs.append(f"{left}: on the right side (Z >= 0), expected Z < 0")
        if not k[right][2] > 0:
            probs.append(f"{right}: on the left side (Z <= 0), expected Z > 0")
    m = k["handle_left"] * [1, 1, -1]
    if np.linalg.norm(m - k["handle_right"]) > 0.03:
        probs.append(f"handle_left: not the mirror image of handle_right "
                     f"({np.linalg.norm(m - k['handle_right']) * 100:.1f} cm apart)")
    if k["handle_right"][1] < k["steer_bottom"][1]:
        probs.append("handle_right: below the steering axis' bottom")
    if has_crank:
        vl = (k["pedal_left"] - k["crank_axle"])[:2]
        vr = (k["pedal_right"] - k["crank_axle"])[:2]
        if np.linalg.norm(vl + vr) > 0.03:
            probs.append(f"pedal_left: not opposite pedal_right about crank_axle "
                         f"({np.linalg.norm(vl + vr) * 100:.1f} cm off)")
        if not 0.05 < np.linalg.norm(vr) < 0.25:
            probs.append(f"pedal_right: {np.linalg.norm(vr) * 100:.0f} cm from crank_axle (crank length 5-25 cm)")
    return probs

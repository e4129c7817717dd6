"""Where everything goes: the side-view geometry of a bike from its spec (canonical frame, no bpy).

Canonical frame: X forward, Y up, Z to the rider's right; ground Y = 0; the bottom bracket at
(0, bb_height, 0).  Geometry follows the frame-builder's definitions: reach/stack to the
head-tube top, fork axle-to-crown length and offset measured along/normal to the steering axis.
The mesh builders and the keypoints both read this one layout, so they cannot disagree.
"""
import numpy as np

LOWER_HEADSET = 0.012   # head-tube bottom to fork crown, along the steering axis
STEM_HEIGHT = 0.04      # stem clamp height on the steerer
KP_INSET = 0.005        # keypoints on the steering axis sit this far inside the head tube


def _v(x, y, z=0.0):
    return np.array([x, y, z], dtype=float)


def _unit(v):
    return v / np.linalg.norm(v)


def wheelbase(spec):
    kind = spec["rideable"]
    if kind == "bicycle":
        lay = bicycle_layout(spec)
    elif kind == "kick_scooter":
        lay = scooter_layout(spec)
    else:
        lay = motorcycle_layout(spec)
    return float(lay["front_axle"][0] - lay["rear_axle"][0])


def _steering(ha_deg):
    ha = np.radians(ha_deg)
    u = _v(-np.cos(ha), np.sin(ha))   # up the steering axis (leans back)
    n = _v(np.sin(ha), np.cos(ha))    # normal to it, forward
    return u, n


def bicycle_layout(s):
    R = s["wheel_diameter_m"] / 2
    h = s["bb_height_m"]
    L = {}
    L["R"] = R
    L["bb"] = bb = _v(0, h)
    drop = R - h
    L["rear_axle"] = _v(-np.sqrt(s["chainstay_m"] ** 2 - drop ** 2), R)
    u, n = _steering(s["head_angle_deg"])
    L["u"], L["n"] = u, n
    ha = np.radians(s["head_angle_deg"])
    a2c = R + s["fork_clearance_m"]
    off = s["fork_offset_m"]
    # head-tube bottom height follows from putting the front axle at wheel-radius height
    hb_y = R + (a2c + LOWER_HEADSET) * np.sin(ha) - off * np.cos(ha)
    ht = s["head_tube_m"]
    L["head_top"] = head_top = _v(s["reach_m"], hb_y + ht * np.sin(ha))
    L["head_bottom"] = hb = head_top - ht * u
    L["crown"] = crown = hb - LOWER_HEADSET * u
    L["front_axle"] = crown - a2c * u + off * n
    L["fork_a2c"] = a2c
    sa = np.radians(s["seat_angle_deg"])
    L["sdir"] = sdir = _v(-np.cos(sa), np.sin(sa))
    # saddle and seat post along the seat-tube line
    L["saddle_top"] = bb + s["saddle_height_m"] * sdir
    ftype = s["frame_type"]
    tt_front = head_top - 0.022 * u
    if ftype in ("diamond", "bmx"):
        sl = np.radians(s["top_tube_slope_deg"])
        d = _v(-np.cos(sl), -np.sin(sl))
        # tt_front + t d = bb + k sdir
        A = np.array([[d[0], -sdir[0]], [d[1], -sdir[1]]])
        t, k = np.linalg.solve(A, (bb - tt_front)[:2])
        k = min(k, s["saddle_height_m"] - 0.12)
    else:  # step-through / cruiser: a shorter seat tube, no top tube at saddle height
        k = min(s["saddle_height_m"] - 0.14, 0.30 + 0.6 * (s["saddle_height_m"] - 0.5))
    L["seat_cluster"] = bb + k * sdir
    L["tt_front"] = tt_front
    L["seat_tube_m"] = float(k)
    L["post_top"] = bb + (s["saddle_height_m"] - 0.045) * sdir
    # cockpit
    L["steerer_top"] = head_top + (s["spacer_m"] + STEM_HEIGHT + 0.004) * u
    L["stem_clamp"] = sc = head_top + (s["spacer_m"] + STEM_HEIGHT / 2) * u
    a = np.radians(s["stem_angle_deg"])
    L["bar_clamp"] = sc + s["stem_length_m"] * (np.cos(a) * n + np.sin(a) * u)
    L["bar_path"], L["grip_centre"] = handlebar_path(s, L["bar_clamp"])
    # crank
    L["crank_q"] = q = 0.072 if s["style"] != "kids" else 0.062
    L["pedal_out"] = po = 0.062 if s["style"] != "kids" else 0.05
    cl = s["crank_length_m"]
    L["pedal_right"] = bb + _v(cl, 0, q + po)
    L["pedal_left"] = bb + _v(-cl, 0, -(q + po))
    L["chainline"] = {"mountain": 0.052, "bmx": 0.05}.get(s["style"], 0.045)
    L["rear_half_spacing"] = s["rear_spacing_m"] / 2
    L["front_half_spacing"] = 0.055 if s["fork_type"] == "suspension" else 0.05
    return L


def handlebar_path(s, bc):
    """Centreline of the right half of the bar (canonical, from the clamp outwards) and the
    right hand position: grip centre, or the brake hood for drop bars."""
    w = s["bar_width_m"] / 2
    kind = s["handlebar"]
    if kind == "drop":
        r, d = s["bar_reach_m"], s["bar_drop_m"]
        flare = 0.02 if s["style"] == "gravel" else 0.0
        pts = [bc, bc + _v(0, 0, w - 0.07), bc + _v(0.55 * r, 0, w - 0.015), bc + _v(r, -0.025, w - 0.005),
               bc + _v(0.9 * r, -0.65 * d, w + 0.5 * flare), bc + _v(0.35 * r, -d, w + flare),
               bc + _v(-0.07, -d + 0.008, w + flare)]
        hand = bc + _v(0.92 * r, -0.012, w - 0.008)  # on the bar at the hood
        return np.array(pts), hand
    rise = s["bar_rise_m"]
    back = s["bar_reach_m"]
    if kind == "riser":
        pts = [bc, bc + _v(0, 0, 0.07), bc + _v(-0.005, 0.6 * rise, 0.13), bc + _v(-0.01, rise, 0.19),
               bc + _v(-0.01 - 0.08 * (w - 0.19), rise, w)]
    elif kind == "swept":
        pts = [bc, bc + _v(0, 0, 0.06), bc + _v(0.01, 0.6 * rise, 0.14), bc + _v(-0.25 * back, rise, 0.5 * w + 0.08),
               bc + _v(-0.75 * back, rise, w - 0.01), bc + _v(-back - 0.06, rise - 0.01, w)]
    elif kind == "bmx":
        pts = [bc, bc + _v(0, 0, 0.09), bc + _v(-back, rise, 0.27), bc + _v(-back - 0.03, rise + 0.01, 0.31),
               bc + _v(-back - 0.06, rise + 0.01, w)]
    else:  # flat
        pts = [bc, bc + _v(-0.035, 0, w)]
    pts = np.array(pts)
    # grip centre: 0.065 m in from the bar end along the last segment
    d_end = _unit(pts[-1] - pts[-2])
    return pts, pts[-1] - 0.065 * d_end


def scooter_layout(s):
    R = s["wheel_diameter_m"] / 2
    L = {"R": R}
    dl = s["deck_length_m"]
    deck_top = s["deck_height_m"]
    L["deck_top"] = deck_top
    L["deck_thick"] = 0.03
    # canonical origin X at the deck centre (the rider's feet); rear axle behind the deck end
    L["rear_axle"] = _v(-dl / 2 - R * 0.55, R)
    u, n = _steering(s["head_angle_deg"])
    L["u"], L["n"] = u, n
    L["front_axle"] = fa = _v(dl / 2 + 0.09 + R * 0.6, R)
    # steering axis through a point slightly behind/above the front axle (fork offset 0.02)
    base = fa - 0.02 * n
    L["head_bottom"] = hb = base + ((deck_top + 0.06 - base[1]) / u[1]) * u
    L["head_top"] = hb + 0.10 * u
    L["crown"] = hb - 0.01 * u
    L["bar_clamp"] = hb + ((s["bar_height_m"] - hb[1]) / u[1]) * u
    w = s["bar_width_m"] / 2
    bc = L["bar_clamp"]
    L["bar_path"] = np.array([bc, bc + _v(0, 0, w)])
    L["grip_centre"] = bc + _v(0, 0, w - 0.06)
    L["bb"] = _v(0, deck_top - L["deck_thick"] / 2)   # deck centre: stands in for the crank axle
    return L


def motorcycle_layout(s):
    R = s["wheel_diameter_m"] / 2
    L = {"R": R}
    wb = s.get("wheelbase_target_m") or 1.42
    peg_y = s["peg_height_m"]
    # canonical origin X at the footpeg axis (stands in for the crank axle)
    L["bb"] = _v(0, peg_y)
    L["rear_axle"] = _v(-0.55, R)
    L["front_axle"] = fa = _v(-0.55 + wb, R)
    u, n = _steering(s["head_angle_deg"])
    L["u"], L["n"] = u, n
    off = 0.03  # triple-clamp offset
    L["fork_base"] = fa
    # lower triple clamp 0.70 m up the fork legs, upper 0.17 above it
    L["fork_top"] = ft = fa + 0.72 * u
    L["head_bottom"] = hb = ft - off * n
    L["head_top"] = hb + 0.17 * u
    L["crown"] = hb - 0.01 * u
    L["seat_top"] = _v(-0.22, s["seat_height_m"])
    bc = L["head_top"] + 0.06 * u - 0.08 * n
    L["bar_clamp"] = bc
    w = s["bar_width_m"] / 2
    L["bar_path"] = np.array([bc, bc + _v(0, 0, 0.12), bc + _v(-0.08, 0.04, w)])
    L["grip_centre"] = L["bar_path"][-1] - 0.07 * _unit(L["bar_path"][-1] - L["bar_path"][-2])
    L["peg_z"] = 0.17
    L["pedal_right"] = _v(0, peg_y, L["peg_z"])
    L["pedal_left"] = _v(0, peg_y, -L["peg_z"])
    L["swingarm_pivot"] = _v(0.05, 0.40)
    return L


def layout_for(spec):
    return {"bicycle": bicycle_layout, "kick_scooter": scooter_layout,
            "motorcycle": motorcycle_layout}[spec["rideable"]](spec)


def keypoints(spec, L=None):
    """The eleven docs/contract.md keypoints (canonical, metres) for a spec."""
    L = L or layout_for(spec)
    kind = spec["rideable"]
    u = L["u"]
    kp = {}
    if kind == "bicycle":
        kp["seat"] = L["saddle_top"] - _v(0, 0.004)
        kp["pedal_left"], kp["pedal_right"] = L["pedal_left"], L["pedal_right"]
    elif kind == "kick_scooter":
        # no saddle or pedals: the standing rider's feet on the deck
        top = L["deck_top"] - 0.004
        kp["seat"] = _v(-0.12, top)
        kp["pedal_left"], kp["pedal_right"] = _v(0.05, top, -0.035), _v(0.05, top, 0.035)
    else:
        kp["seat"] = L["seat_top"] - _v(0, 0.004)
        kp["pedal_left"], kp["pedal_right"] = L["pedal_left"], L["pedal_right"]
    kp["steer_top"] = L["head_top"] - KP_INSET * u
    kp["steer_bottom"] = L["head_bottom"] + KP_INSET * u
    g = L["grip_centre"]
    kp["handle_right"] = g.copy()
    kp["handle_left"] = g * _v(1, 1, -1)
    kp["crank_axle"] = L["bb"].copy()
    kp["front_axle"] = L["front_axle"].copy()
    kp["rear_axle"] = L["rear_axle"].copy()
    kp["ground"] = _v(L["rear_axle"][0], 0.0)
    return {k: [float(c) for c in v] for k, v in kp.items()}


KEYPOINT_NAMES = ["seat", "steer_top", "steer_bottom", "handle_left", "handle_right", "crank_axle",
                  "pedal_left", "pedal_right", "front_axle", "rear_axle", "ground"]


def part_keypoints(spec):
    """Which keypoints each part carries (docs/contract.md names)."""
    frame = ["seat", "rear_axle", "ground", "steer_top", "steer_bottom", "crank_axle"]
    steering = ["steer_top", "steer_bottom", "handle_left", "handle_right", "front_axle"]
    if spec["rideable"] == "bicycle":
        return {"frame": frame, "steering": steering, "crank": ["crank_axle", "pedal_left", "pedal_right"]}
    return {"frame": frame + ["pedal_left", "pedal_right"], "steering": steering}


def bone_parent(name, spec):
    """The part bone that carries keypoint `name`."""
    if name in ("handle_left", "handle_right", "front_axle"):
        return "steering"
    if name in ("pedal_left", "pedal_right") and spec["rideable"] == "bicycle":
        return "crank"
    return "frame"

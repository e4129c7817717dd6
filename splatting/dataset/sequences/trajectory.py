"""A cyclist's trajectory on the road plane: a manoeuvre -> per-frame 8-DoF poses and motion labels.

Pure numpy, a function of its arguments alone (the draw in draw.py supplies them from the
sequence's Generator), so every frame of a sequence is a function of (config, sequence index).

Model (docs/sequences.md):
- the path is that of the REAR wheel's contact point, given as a curvature profile kappa(s) over
  arc length s (sums of raised-cosine bumps: curvature is continuous, heading C2) and a speed
  profile v(t) (constant, or raised-cosine ramps down to 0 / up from 0); both are integrated on a
  fine grid (SUBSTEPS per frame, arc-length step DS) and sampled at the frames;
- heading theta_Y = the path's tangent (the rear wheel rolls without side slip: the kinematic
  bicycle), the pose's origin (the ground under the crank axle) lies `b` ahead of the rear
  contact point along the heading;
- steering: the ground-plane steer angle delta = atan(L kappa) (L the wheelbase) is the front
  wheel's heading relative to the frame; a rotation theta_s about the steering axis, raked back
  by the caster angle eps, turns the wheel's heading by delta with tan(delta) = tan(theta_s) cos(eps),
  so theta_s = atan(tan(delta) / cos(eps)).  Trail approximation: the trail (a few cm) moves the
  front contact point and the lean tilts the steering axis; both are neglected (effects of
  order trail/L and lean x steer on the heading);
- lean theta_X = -atan(v^2 kappa / g): the steady-turn balance of gravity and the centripetal
  force (kappa > 0 turns left = towards canonical -Z, and the bike leans into the turn);
- wheels: rear wheel angle = s / r (rolling without slip, r = the axle height); pedals: crank
  angle rate = wheel angular rate / gear ratio while the rider pedals (v > 0 and not braking),
  constant while coasting, braking or standing.
"""
import math

import numpy as np

G = 9.81
SUBSTEPS = 20           # fine time steps per frame
DS = 0.005              # arc-length step of the path integration (m)
BRAKING = -0.05         # dv/dt below this (m/s^2): the rider coasts (pedals still)

MANOEUVRES = ("straight", "turn_left", "turn_right", "cross", "overtake", "stop", "start", "swerve")


def bike_geometry(keypoints):
    """{wheelbase L, rear offset b (rear contact -> crank origin), wheel radius r, caster eps (rad),
    trail (m)} from a bike's canonical keypoints (X forward, Y up)."""
    k = {n: np.asarray(v, float) for n, v in keypoints.items()}
    rear, front = k["rear_axle"], k["front_axle"]
    L = float(front[0] - rear[0])
    axis = k["steer_top"] - k["steer_bottom"]
    eps = math.atan2(-axis[0], axis[1])  # raked back: the top lies behind the bottom
    # trail: how far the front contact point (under the axle) lies behind where the steering axis meets the ground
    t = -k["steer_bottom"][1] / axis[1]
    ground_x = k["steer_bottom"][0] + t * axis[0]
    return {"L": L, "b": float(-rear[0]), "r": float(rear[1]), "eps": float(eps),
            "trail": float(ground_x - front[0])}


def bumps(s, spec):
    """Curvature at arc lengths s of a list of raised-cosine bumps (s0, length, peak)."""
    out = np.zeros_like(s)
    for s0, ln, peak in spec:
        u = (s - s0) / ln
        m = (u >= 0) & (u <= 1)
        out[m] += peak * 0.5 * (1.0 - np.cos(2 * math.pi * u[m]))
    return out


def turn_bump(s0, angle, radius):
    """A bump turning the heading by `angle` (rad, + = left) whose tightest radius is `radius`."""
    # peak curvature 1/radius; a raised cosine integrates to peak * length / 2 = angle
    ln = 2 * abs(angle) * radius
    return (s0, ln, math.copysign(1.0 / radius, angle))


def lane_change(s0, offset, length):
    """Two bumps (out, back) moving the path sideways by about `offset` (m, + = left) over 2 x length."""
    peak = 2.0 * offset / length ** 2  # heading peaks at peak*length/2, lateral ~ heading_peak * length
    return [(s0, length, peak), (s0 + length, length, -peak)]


def speed_profile(t, p):
    """v(t) of a speed programme {kind: cruise|stop|start, v, t0, ramp}."""
    v, kind = p["v"], p["kind"]
    if kind == "cruise":
        return np.full_like(t, v)
    u = np.clip((t - p["t0"]) / p["ramp"], 0.0, 1.0)
    ramp = 0.5 * (1.0 - np.cos(math.pi * u))  # 0 -> 1, zero slope at both ends
    return v * (1.0 - ramp) if kind == "stop" else v * ramp


def integrate(n_frames, fps, speed, curvature, geom, start_xz, start_heading_deg, gear_ratio, pedal0_deg):
    """Per frame (arrays of length n_frames): pose fields and motion labels.

    speed: dict for speed_profile; curvature: list of bumps; start_xz: rear contact point at t = 0;
    start_heading_deg: theta_Y at t = 0 (pose convention: forward = (cos, 0, -sin))."""
    n_fine = (n_frames - 1) * SUBSTEPS + 1
    t = np.arange(n_fine) / (fps * SUBSTEPS)
    v = speed_profile(t, speed)
    dt = 1.0 / (fps * SUBSTEPS)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])  # trapezoid: exact for the ramps to O(dt^2)
    # the path in arc length on its own fine grid
    s_max = s[-1] + 1.0
    sg = np.arange(0.0, s_max + DS, DS)
    kg = bumps(sg, curvature)
    psi_g = math.radians(start_heading_deg) + np.concatenate([[0.0], np.cumsum(0.5 * (kg[1:] + kg[:-1]) * DS)])
    fx, fz = np.cos(psi_g), -np.sin(psi_g)
    xg = start_xz[0] + np.concatenate([[0.0], np.cumsum(0.5 * (fx[1:] + fx[:-1]) * DS)])
    zg = start_xz[1] + np.concatenate([[0.0], np.cumsum(0.5 * (fz[1:] + fz[:-1]) * DS)])
    psi = np.interp(s, sg, psi_g)
    kap = np.interp(s, sg, kg)
    rear = np.column_stack([np.interp(s, sg, xg), np.interp(s, sg, zg)])
    fwd = np.column_stack([np.cos(psi), -np.sin(psi)])
    origin = rear + geom["b"] * fwd
    acc = np.gradient(v, dt)
    pedalling = (v > 1e-6) & (acc >= BRAKING)
    crank_rate = np.where(pedalling, v / geom["r"] / gear_ratio, 0.0)  # rad/s
    crank = math.radians(pedal0_deg) + np.concatenate([[0.0], np.cumsum(0.5 * (crank_rate[1:] + crank_rate[:-1]) * dt)])
    vel = np.column_stack([np.gradient(origin[:, 0], dt), np.gradient(origin[:, 1], dt)])
    delta = np.arctan(geom["L"] * kap)
    theta_s = np.arctan(np.tan(delta) / math.cos(geom["eps"]))
    lean = -np.arctan(v ** 2 * kap / G)
    f = np.arange(n_frames) * SUBSTEPS
    return {
        "t": t[f], "s": s[f], "speed": v[f], "accel": acc[f], "kappa": kap[f],
        "theta_y_deg": np.degrees(psi[f]), "theta_x_deg": np.degrees(lean[f]), "theta_s_deg": np.degrees(theta_s[f]),
        "steer_ground_deg": np.degrees(delta[f]),
        "theta_p_deg": np.degrees(crank[f]) % 360.0, "crank_rad": crank[f], "crank_rate": crank_rate[f],
        "pedalling": pedalling[f], "wheel_rad": s[f] / geom["r"], "wheel_rate": v[f] / geom["r"],
        # the wheels' rolling angle (deg, unwrapped) for the model's wheel sub-parts: rolling
        # without slip, angle = distance / radius, whether pedalling or coasting
        "wheel_deg": np.degrees(s[f] / geom["r"]), "fine_wheel_deg": np.degrees(s / geom["r"]),
        "rear_xz": rear[f], "origin_xz": origin[f], "velocity_xz": vel[f],
        "lateral_accel": v[f] ** 2 * kap[f],
        # the fine grid's poses (crank and heading unwrapped): sub-frame poses for motion blur (blur.py)
        "fine_t": t, "fine_pose": np.column_stack([np.degrees(crank), np.degrees(theta_s), np.degrees(lean), np.degrees(psi),
                                                   np.zeros(n_fine), origin[:, 0], np.zeros(n_fine), origin[:, 1]]),
    }


def poses(traj):
    """(n, 8) poses in the contract's field order from an integrate() result."""
    n = len(traj["t"])
    return np.column_stack([traj["theta_p_deg"], traj["theta_s_deg"], traj["theta_x_deg"], traj["theta_y_deg"],
                            np.zeros(n), traj["origin_xz"][:, 0], np.zeros(n), traj["origin_xz"][:, 1]])


def crossing_frames(x, heading_deg, lane_half_width, min_angle_deg=10.0):
    """Per frame: True while the cyclist crosses the camera's path (the line X = 0, the ego's lane
    |X| <= lane_half_width): from the first frame its heading turns towards the path (the lateral
    component of its direction points at X = 0 with at least min_angle_deg off the road) until it
    is past the far edge of the lane.  A turn towards the path that turns away again before reaching
    the lane (an overtake's or a swerve's) is no crossing: its frames are cleared.  x: lateral
    positions (world X), heading_deg: theta_Y."""
    x = np.asarray(x, float)
    lateral = np.cos(np.radians(heading_deg))  # forward_x = cos(theta_Y)
    out = np.zeros(len(x), bool)
    side, start, reached = 0.0, 0, False
    state = "before"
    thr = math.sin(math.radians(min_angle_deg))
    for i in range(len(x)):
        if state == "before":
            s = math.copysign(1.0, x[i]) if x[i] != 0 else 0.0
            if s != 0 and -s * lateral[i] >= thr and abs(x[i]) > 0:
                state, side, start, reached = "crossing", s, i, False
        if state == "crossing":
            reached = reached or x[i] * side <= lane_half_width
            if x[i] * side < -lane_half_width:
                state = "after"
            elif not reached and -side * lateral[i] < 0:  # turned away before the lane: not a crossing
                out[start:i] = False
                state = "before"
            else:
                out[i] = True
    return out

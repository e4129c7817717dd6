"""The random choices of one street sequence: ego motion, background, and per cyclist its bike,
rider, manoeuvre, speed, gear and placement; the trajectories that follow from them.

A pure function of (config, sequence index): numpy's Generator seeded with [seed, sequence, TAG]
draws everything in a fixed order, and the trajectories are deterministic numpy (trajectory.py).
Every frame of the sequence calls this again (it costs milliseconds), so frames can be rendered
in any order, by any worker, and resumed.

World as in street mode (docs/street_scenes.md): road plane Y = 0, the road along world +Z; the
ego camera starts at (0, height, 0) and moves along +Z at the drawn ego speed (or stands).  Where
instances may stand is the world's: StreetWorld here, a KITTI frame's in in_frames.FrameWorld.
"""
import functools
import math

import numpy as np

from cyclist_formats.bike_folder import read_keypoints
from splatting.cyclist.assets import bike_dir
from splatting.dataset import camera_presets
from splatting.dataset.sequences import trajectory as tj
from splatting.dataset.street import road_heading
from splatting.rider.ik.foot_down import lean_deg

TAG = 2029
SIGNAL_TAG = 7  # the arm signals' own Generator: [seed, sequence, TAG, SIGNAL_TAG, track index]
FOOT_TAG = 11  # the foot-down side's own Generator: [seed, sequence, TAG, FOOT_TAG, track index]
STOPPED_MPS = 0.05  # below this a stopping rider has a foot on the road (the `stopped` intention's bound)
FOOT_LEAN_RAMP_S = 0.5  # the bike tilts onto the grounded foot over this time after stopping
MAX_RAMP_ACCEL = 3.5  # m/s^2: the hardest stop or start a short sequence may ask for  # keeps the sequence draws apart from the single-image draws of the same seed


@functools.lru_cache(maxsize=64)
def _geometry(bike, root):
    return tj.bike_geometry(read_keypoints(bike_dir(bike, root)))


def geometry(cfg, bike):
    return _geometry(bike, cfg.bikes_root)


def _count(rng, lohi):
    return int(rng.integers(int(lohi[0]), int(lohi[1]) + 1))


def manoeuvre_plan(rng, manoeuvre, sq, duration, v_lo, v_hi, a_max, x0, psi0_deg):
    """(speed programme, curvature bumps, cruising speed) of one manoeuvre (docs/sequences.md)."""
    v = float(rng.uniform(v_lo, v_hi))
    speed = {"kind": "cruise", "v": v}
    bumps = []
    r_lo, r_hi = sq.turn_radius_m
    if manoeuvre in ("turn_left", "turn_right"):
        radius = max(float(rng.uniform(r_lo, r_hi)), v * v / a_max)
        s0 = v * duration * float(rng.uniform(0.15, 0.4))
        bumps = [tj.turn_bump(s0, math.pi / 2 if manoeuvre == "turn_left" else -math.pi / 2, radius)]
    elif manoeuvre == "cross":  # slower and tighter than a turn at a junction: across the road in a few seconds
        v = float(rng.uniform(v_lo, 0.5 * (v_lo + v_hi)))
        speed["v"] = v
        radius = max(r_lo * float(rng.uniform(1.0, 1.5)), v * v / a_max)
        angle = math.radians(float(rng.uniform(60.0, 90.0)))
        # a left turn (+) points the bike to -sin(psi0) in X; the path (X = 0) lies at -sign(x0)
        sign = math.copysign(1.0, math.sin(math.radians(psi0_deg)) * x0)
        s0 = v * duration * float(rng.uniform(0.05, 0.25))
        bumps = [tj.turn_bump(s0, sign * angle, radius)]
    elif manoeuvre in ("overtake", "swerve"):
        if manoeuvre == "overtake":
            v = float(rng.uniform(0.5 * (v_lo + v_hi), v_hi))
            speed["v"] = v
            off, ln = float(rng.uniform(1.2, 2.0)), v * float(rng.uniform(1.2, 2.0))
            hold = v * float(rng.uniform(1.0, 2.0))
        else:
            off, ln, hold = float(rng.uniform(0.5, 1.0)), v * float(rng.uniform(0.4, 0.7)), 0.0
        off *= 1.0 if rng.uniform() < 0.5 else -1.0
        ln = max(ln, 2.5, math.sqrt(2.0 * abs(off) * v * v / a_max))  # peak v^2 kappa <= a_max
        s0 = v * duration * float(rng.uniform(0.1, 0.3))
        bumps = tj.lane_change(s0, off, ln) + tj.lane_change(s0 + 2 * ln + hold, -off, ln)
    elif manoeuvre in ("stop", "start"):
        # a raised-cosine ramp's steepest slope is v pi / (2 ramp); the ramp ends within the
        # sequence (then the peak braking / acceleration may rise, up to MAX_RAMP_ACCEL)
        a = float(rng.uniform(1.0, 2.5)) if manoeuvre == "stop" else float(rng.uniform(0.8, 1.5))
        t0 = duration * float(rng.uniform(0.1, 0.4) if manoeuvre == "stop" else rng.uniform(0.05, 0.3))
        ramp = min(math.pi * v / (2.0 * a), 0.9 * (duration - t0))
        v = max(min(v, 2.0 * ramp * MAX_RAMP_ACCEL / math.pi), min(v, v_lo))
        speed = {"kind": manoeuvre, "v": v, "t0": t0, "ramp": ramp}
    return speed, bumps, v


def intention(manoeuvre, traj, crossing):
    """Per-frame intention labels (docs/sequences.md)."""
    out = []
    for i in range(len(traj["t"])):
        k, v, a = traj["kappa"][i], traj["speed"][i], traj["accel"][i]
        if crossing[i]:
            lab = "crossing"
        elif manoeuvre in ("turn_left", "turn_right") and abs(k) > 1e-3:
            lab = "turning_left" if k > 0 else "turning_right"
        elif manoeuvre in ("overtake", "swerve", "cross") and abs(k) > 1e-3:
            lab = {"overtake": "overtaking", "swerve": "swerving", "cross": "turning_left" if k > 0 else "turning_right"}[manoeuvre]
        elif v < 0.05:
            lab = "stopped"
        elif a < tj.BRAKING:
            lab = "stopping"
        elif a > 0.05:
            lab = "starting"
        else:
            lab = "riding"
        out.append(lab)
    return out


def turn_start(bumps):
    """(arc length s0 at which the path starts to turn, 'left' | 'right') of a turn or crossing."""
    s0, _, peak = bumps[0]
    return s0, "left" if peak > 0 else "right"


def signal_frames(rng, manoeuvre, traj, speed, bumps, sq, duration):
    """Per frame the arm signal of one cyclist (docs/sequences.md, signals): with probability
    signal_share a turn or crossing is announced by the left / right arm from a drawn lead time
    before the turn starts (its curvature leaves 0) until it starts, a stop by the stop signal
    before the braking starts; with probability one_handed_share a `straight` rider rides
    one-handed for a drawn 1-4 s.  Always three draws (share, lead, span), so the count of draws
    does not depend on the manoeuvre."""
    t = traj["t"]
    out = np.full(len(t), "none", dtype=object)
    u, lead, start = float(rng.uniform()), float(rng.uniform(*sq.signal_lead_s)), float(rng.uniform())
    span = 1.0 + 3.0 * float(rng.uniform())
    if manoeuvre in ("turn_left", "turn_right", "cross") and bumps and u < sq.signal_share:
        s0, side = turn_start(bumps)
        t0 = float(np.interp(s0, traj["s"], t)) if s0 < traj["s"][-1] else math.inf
        out[(t >= t0 - lead) & (t < t0)] = side
    elif manoeuvre == "stop" and u < sq.signal_share:
        out[(t >= speed["t0"] - lead) & (t < speed["t0"])] = "stop"
    elif manoeuvre == "straight" and u < sq.one_handed_share:
        a = start * max(duration - span, 0.0)
        out[(t >= a) & (t < a + span)] = "one_handed"
    return [str(x) for x in out]


class StreetWorld:
    """Where a street sequence's instances may stand: the generated street (docs/street_scenes.md),
    the driving camera of the preset; any spot within `street.lateral_m`, only the footprint discs
    kept apart.  (Sequences in a KITTI frame have their own world: sequences/in_frames.py.)"""

    def __init__(self, cfg, rng, t):
        self.cfg, st = cfg, cfg.street
        self.spec = camera_presets.resolve(cfg.camera)
        ego = cfg.sequence.ego
        self.ego_speed = float(rng.uniform(*ego.speed_mps)) if ego.motion == "moving" else 0.0
        self.ego_z = self.ego_speed * t
        self.axis_deg = road_heading(st.road_heading_deg)

    def spot(self, rng):
        """(world X, distance ahead of the camera) of a drawn spot: its distance and image column."""
        st, cam = self.cfg.street, self.spec
        z_rel = float(rng.uniform(*st.distance_m))
        u = float(rng.uniform(-st.border_margin, 1.0 + st.border_margin)) * cam["width"]
        return -(u - cam["cx"]) * z_rel / cam["fx"], z_rel  # image-right is world -X

    def usable(self, x, z_ahead):
        lo, hi = self.cfg.street.lateral_m
        return lo <= x <= hi

    def track_ok(self, kind, pose):
        return True, {}

    def camera(self, checks):
        return {"preset": self.spec["preset"]}

    def background(self, rng):
        kinds = self.cfg.backgrounds.kinds
        return {"kind": kinds[int(rng.integers(len(kinds)))], "seed": int(rng.integers(2 ** 31))}


def foot_down(rng, manoeuvre, traj, pose):
    """Per frame "left" / "right" / "none": a `stop` rider puts a foot (side drawn by rng) on the
    road from the frame it stands still, and the bike leans onto it over FOOT_LEAN_RAMP_S (pose's
    and traj's theta_X, and the blur's fine poses, are updated in place)."""
    n = len(traj["t"])
    if manoeuvre != "stop":
        return ["none"] * n
    side = "left" if rng.uniform() < 0.5 else "right"
    still = np.flatnonzero(traj["speed"] < STOPPED_MPS)
    if not len(still):
        return ["none"] * n
    t0 = float(traj["t"][still[0]])

    def lean(t):
        u = np.clip((np.asarray(t) - t0) / FOOT_LEAN_RAMP_S, 0.0, 1.0)
        return lean_deg(side) * 0.5 * (1.0 - np.cos(math.pi * u)) * (np.asarray(t) >= t0)

    pose[:, 2] = traj["theta_x_deg"] = traj["theta_x_deg"] + lean(traj["t"])
    traj["fine_pose"][:, 2] = traj["fine_pose"][:, 2] + lean(traj["fine_t"])
    return [side if traj["t"][f] >= t0 else "none" for f in range(n)]


def draw_sequence(cfg, seq):
    """Sequence `seq` -> {"ego_speed", "camera", "background", "instances": [...], "dropped"}; each
    instance {kind, bike, rider, manoeuvre, poses (n, 8), traj, crossing, intention, gear_ratio, geometry}.
    The world is the generated street (mode street) or a KITTI frame (mode frames: in_frames.FrameWorld)."""
    sq, st = cfg.sequence, cfg.street
    rng = np.random.default_rng([cfg.seed, seq, TAG])
    n, fps = int(sq.length), float(sq.fps)
    duration = (n - 1) / fps
    t = np.arange(n) / fps
    if cfg.mode == "frames":
        from splatting.dataset.sequences.in_frames import FrameWorld
        world = FrameWorld(cfg, seq, t)
    else:
        world = StreetWorld(cfg, rng, t)
    ego_z = world.ego_z
    names = list(type(sq.manoeuvres).model_fields)  # declaration order (MANOEUVRES)
    w = np.array([float(getattr(sq.manoeuvres, m)) for m in names])
    n_cyc = _count(rng, st.cyclists) if cfg.riders else 0
    n_park = _count(rng, st.parked_bikes)
    r_fp = float(st.footprint_radius_m)
    a_max = float(sq.max_lateral_accel_mps2)
    v_lo, v_hi = sq.speed_mps
    mid = n // 2
    placed, out, dropped, checks = [], [], 0, []
    for kind in ["cyclist"] * n_cyc + ["parked"] * n_park:
        bike = cfg.bikes[int(rng.integers(len(cfg.bikes)))]
        rider = cfg.riders[int(rng.integers(len(cfg.riders)))] if kind == "cyclist" else None
        geom = geometry(cfg, bike)
        man = names[int(rng.choice(len(names), p=w / w.sum()))] if kind == "cyclist" else "parked"
        cadence = float(rng.uniform(*sq.cadence_rpm))
        pedal0 = float(rng.uniform(0.0, 360.0))
        steer = float(rng.uniform(*st.parked_steer_deg))
        got = None
        for _ in range(int(st.max_tries)):
            x, z_rel = world.spot(rng)
            oncoming = bool(rng.uniform() < st.oncoming_share)
            plan_rng = np.random.default_rng([cfg.seed, seq, TAG, len(placed), int(rng.integers(2 ** 31))])
            if not world.usable(x, z_rel):
                continue
            if kind == "parked":
                yaw = world.axis_deg + float(rng.uniform(-1, 1)) * st.heading_spread_deg
                pose = np.tile([0.0, steer, 0.0, yaw, 0.0, x, 0.0, ego_z[mid] + z_rel], (n, 1))
                traj = {"t": t, "speed": np.zeros(n), "kappa": np.zeros(n), "accel": np.zeros(n),
                        "velocity_xz": np.zeros((n, 2)), "origin_xz": pose[:, [5, 7]], "wheel_rad": np.zeros(n),
                        "crank_rate": np.zeros(n), "wheel_rate": np.zeros(n), "lateral_accel": np.zeros(n)}
                gear = None
            else:
                psi0 = world.axis_deg + (180.0 if oncoming else 0.0)
                x0 = x if man == "cross" else 0.0
                if man == "cross" and abs(x0) < 2.0:  # a crossing starts beside the ego's lane
                    x0 = math.copysign(float(rng.uniform(2.5, 6.0)), x0 if x0 != 0 else 1.0)
                speed, bumps, v_cruise = manoeuvre_plan(plan_rng, man, sq, duration, v_lo, v_hi, a_max, x0, psi0)
                gear = float(np.clip(v_cruise / geom["r"] / (cadence * 2 * math.pi / 60.0), 1.0, 5.0))
                traj = tj.integrate(n, fps, speed, bumps, geom, (x0, 0.0), psi0, gear, pedal0)
                xz = traj["origin_xz"]
                if man == "cross":  # the ego reaches the crossing point z_rel behind the cyclist
                    past = np.flatnonzero(xz[:, 0] * math.copysign(1.0, x0) <= 0)
                    anchor = int(past[0]) if len(past) else n - 1
                    shift = np.array([0.0, ego_z[anchor] + max(z_rel, 8.0) - xz[anchor, 1]])
                else:
                    anchor = mid
                    shift = np.array([x - xz[anchor, 0], ego_z[anchor] + z_rel - xz[anchor, 1]])
                for key in ("origin_xz", "rear_xz"):
                    traj[key] = traj[key] + shift
                traj["fine_pose"] = traj["fine_pose"] + np.array([0, 0, 0, 0, 0, shift[0], 0, shift[1]])
                pose = tj.poses(traj)
            track = pose[:, [5, 7]]
            if all(np.min(np.sum((track - p) ** 2, 1)) >= (2 * r_fp) ** 2 for p in placed):
                ok, info = world.track_ok(kind, pose)
                if ok:
                    got = (pose, traj, gear, (speed, bumps) if kind == "cyclist" else None)
                    break
        if got is None:
            dropped += 1
            continue
        checks.append(info)
        pose, traj, gear, plan = got
        placed.append(pose[:, [5, 7]])
        rec = {}
        if kind == "cyclist":
            crossing = tj.crossing_frames(traj["origin_xz"][:, 0], traj["theta_y_deg"], sq.lane_half_width_m)
            inten = intention(man, traj, crossing)
            # its own Generator: the signal draws leave every other draw of the sequence as it was
            sig_rng = np.random.default_rng([cfg.seed, seq, TAG, SIGNAL_TAG, len(out)])
            rec["signal"] = signal_frames(sig_rng, man, traj, plan[0], plan[1], sq, duration)
            foot_rng = np.random.default_rng([cfg.seed, seq, TAG, FOOT_TAG, len(out)])
            rec["foot_down"] = foot_down(foot_rng, man, traj, pose)
        else:
            crossing, inten = np.zeros(n, bool), ["parked"] * n
        out.append({"kind": kind, "bike": bike, "rider": rider, "manoeuvre": man, "poses": pose, "traj": traj,
                    "crossing": crossing, "intention": inten, "gear_ratio": gear, "geometry": geom,
                    "plan": plan, **rec})
    sd = {"ego_speed": world.ego_speed, "ego_z": ego_z, "camera": world.camera(checks), "spec": world.spec,
          "background": world.background(rng), "instances": out, "dropped": dropped}
    if cfg.mode == "frames":  # one light gain for the whole sequence: the road around every track
        sd["look_feet_world"] = world.look_feet([i["poses"] for i in out])
    return sd


def frame_draw(sd, f):
    """make_sample's draw dict for frame f of a drawn sequence."""
    inst = [{"kind": i["kind"], "bike": i["bike"], "rider": i["rider"], "pose": [float(x) for x in i["poses"][f]],
             **({"signal": i["signal"][f]} if "signal" in i else {}),
             **({"foot_down": i["foot_down"][f]} if i.get("foot_down", ["none"] * (f + 1))[f] != "none" else {}),
             **({"wheel_deg": float(i["traj"]["wheel_deg"][f])} if "wheel_deg" in i.get("traj", {}) else {})}
            for i in sd["instances"]]
    return with_look({"instances": inst, "dropped": sd["dropped"], "camera": dict(sd["camera"]),
                      "background": dict(sd["background"])}, sd)


def with_look(d, sd):
    """A frame's draw with the sequence's look footing (KITTI frames: the road the light gain is
    measured on, the same in every frame so the gain does not flicker)."""
    if "look_feet_world" in sd:
        d["look_feet_world"] = sd["look_feet_world"]
    return d


def ego_camera(sd, f):
    """The driving camera at frame f: the preset's camera moved by the ego's travel along +Z."""
    return ego_camera_at(sd, sd["ego_z"][f])


def ego_camera_at(sd, z):
    """The driving camera after z metres of travel along +Z (a sub-frame instant: z = speed x t);
    None in a KITTI frame (its own camera, standing: make_sample takes the frame's)."""
    from splatting.raster.camera import from_numpy
    spec = sd["spec"]
    if spec is None:
        return None
    R, T = camera_presets.pose(spec)
    T = T - R @ np.array([0.0, 0.0, z])
    return from_numpy(camera_presets.intrinsics(spec), R, T, spec["width"], spec["height"])


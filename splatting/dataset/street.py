"""Street scenes: where the cyclists and parked bikes of one image stand on the road.

Pure numpy on the sample's Generator (called from generate.draw in a fixed order), so a scene is
a function of (config, index) like everything else.

World: the road is Y = 0; the driving camera stands at (0, height, 0) looking along +Z
(camera_presets).  An instance is placed by
- its distance along the camera's level forward axis, uniform in `street.distance_m`;
- a horizontal image position, uniform over the image width widened by `border_margin` of it on
  both sides (so instances near and across the border happen: truncation), which with the
  distance gives the lateral offset (rejected when outside `street.lateral_m`);
- its heading: `road` = the road direction (`road_heading_deg`, 0 = away from the camera along its
  axis, 90 = crossing from image-left to image-right) plus uniform +-`heading_spread_deg`, turned
  by 180 deg for the `oncoming_share` riding the other way; `uniform` = any direction.
Footprints: every instance occupies a disc of `footprint_radius_m` about its crank axle (a bike is
~1.8 m long, the crank axle near its middle); a placement whose disc meets an earlier one is drawn
again, up to `max_tries` times, after which the instance is left out (recorded as `dropped`).
"""
import math

import numpy as np

from cyclist_formats.pose import POSE_FIELDS

# pose fields the street draws itself (heading and position on the road)
PLACED = ("theta_y_deg", "t_x_m", "t_y_m", "t_z_m")


def heading_to_forward(theta_y_deg):
    """World direction a bike faces at heading theta_y (Ry applied to the canonical +X)."""
    a = math.radians(theta_y_deg)
    return np.array([math.cos(a), 0.0, -math.sin(a)])


def road_heading(road_deg):
    """theta_y of a bike riding along the road direction road_deg (0: world +Z, 90: world -X, the
    camera's image-right)."""
    # forward (cos t, 0, -sin t) = (-sin r, 0, cos r)  ->  t = r - 90
    return float(road_deg) - 90.0


def _count(rng, lohi):
    return int(rng.integers(int(lohi[0]), int(lohi[1]) + 1))


def draw_street(cfg, rng, cam):
    """Instances of one street image: list of {"kind": "cyclist"|"parked", "bike", "rider", "pose"}."""
    s = cfg.street
    n_cyc = _count(rng, s.cyclists) if cfg.riders else 0
    n_park = _count(rng, s.parked_bikes)
    kinds = ["cyclist"] * n_cyc + ["parked"] * n_park
    placed, out, dropped = [], [], 0
    r = float(s.footprint_radius_m)
    for kind in kinds:
        bike = cfg.bikes[int(rng.integers(len(cfg.bikes)))]
        rider = cfg.riders[int(rng.integers(len(cfg.riders)))] if kind == "cyclist" else None
        pose = {k: float(rng.uniform(*getattr(cfg.pose, k))) for k in POSE_FIELDS if k not in PLACED}
        if kind == "parked":
            pose["theta_s_deg"] = float(rng.uniform(*s.parked_steer_deg))
        spot = None
        for _ in range(int(s.max_tries)):
            z = float(rng.uniform(*s.distance_m))
            u = float(rng.uniform(-s.border_margin, 1.0 + s.border_margin)) * cam["width"]
            x = -(u - cam["cx"]) * z / cam["fx"]  # image-right is world -X
            if s.heading == "uniform":
                yaw = float(rng.uniform(-180.0, 180.0))
            else:
                yaw = road_heading(s.road_heading_deg) + float(rng.uniform(-1, 1)) * s.heading_spread_deg
                if rng.uniform() < s.oncoming_share:
                    yaw += 180.0
            yaw = (yaw + 180.0) % 360.0 - 180.0
            if not s.lateral_m[0] <= x <= s.lateral_m[1]:
                continue
            if all((x - px) ** 2 + (z - pz) ** 2 >= (2 * r) ** 2 for px, pz in placed):
                spot = (x, z, yaw)
                break
        if spot is None:
            dropped += 1
            continue
        placed.append(spot[:2])
        pose.update(theta_y_deg=spot[2], t_x_m=spot[0], t_y_m=0.0, t_z_m=spot[1])
        out.append({"kind": kind, "bike": bike, "rider": rider, "pose": [pose[k] for k in POSE_FIELDS]})
    return out, dropped

"""Where the inserted cyclists and parked bikes of one frame stand (called from generate.draw).

Pure numpy on the sample's Generator, so a sample is a function of (config, index).  Per instance,
up to `street.max_tries` draws of
- a distance: camera-0 depth z uniform in `street.distance_m` (3-60 m by default), and an image
  column u uniform over the width widened by `street.border_margin` (truncation happens); the
  spot is the road-plane point at that depth seen in that column (through camera 2);
- a heading along the road (road.road_axis: the labelled cars' dominant direction, or the config's
  `street.road_heading_deg`) +- `street.heading_spread_deg`, turned round for `street.oncoming_share`
  (`street.heading: uniform`: any direction);
and the draw is kept only when
- |world X| (lateral offset) is within `street.lateral_m`,
- its footprint (a 1.9 x 0.8 m rectangle along the heading) overlaps no labelled 3D box's footprint
  grown by `insert.box_margin_m` (cars, vans, pedestrians, cyclists..., DontCare has no box) and no
  earlier instance's,
- the instance's 1.8 m height projects into the image (its top above the bottom border),
- with the frame's LiDAR: lidar.ground_support counts road points around the footprint (at least
  `insert.min_ground_points`: the sensor sees road there) and no obstacle points (0.3-2.5 m above the
  road inside it: a pole, a hedge, a wall), and lidar.visible_ground finds no nearer object above
  the road in the spot's direction (it is not inside another object's LiDAR shadow).
`insert.behind_cars_share` of the instances (drawn per instance) are sought just beyond a labelled car,
van, truck or tram instead (0.8-3 m past it along the camera's line of sight, up to half its length
aside): KITTI's cyclists are occluded in 36 % of rows, mostly by parked cars.  Such a spot may lie in the
car's LiDAR shadow (no ground seen, sensor blocked): allowed only when the blocker is the labelled box
(lidar.visible_ground's exception: the box then hides the cyclist in the image too and its label says so).
An instance with no kept draw is left out and counted in `dropped`.  The bike stands on the world
plane Y = 0 (the road plane, frames.road) with no pitch (theta_z = 0), so both tyres touch it.
"""
import numpy as np

from cyclist_formats.pose import POSE_FIELDS
from splatting.dataset.frames import lidar, source
from splatting.dataset.frames.road import CARS, convex_overlap, footprint, rectangle, road_axis, segment_hits_box
from splatting.dataset.street import PLACED, _count

FOOT_L, FOOT_W, HEIGHT = 1.9, 0.8, 1.8  # a cyclist's footprint and height (m) for the checks


def spot(road, z, u):
    """The road-plane point (rect) at camera-0 depth z seen in image column u (camera 2)."""
    K, t = road.K, road.t
    x = (u - K[0, 2]) * (z + t[2]) / K[0, 0] - t[0]
    a, b, c, d = road.plane
    y = -(a * x + c * z + d) / b
    return np.array([x, y, z])


def behind_label(fr, centre_rect):
    """True when a labelled box stands between the sensor and the spot (0.5 m above the road)."""
    a = lidar.sensor_origin_rect(fr.T_velo_to_rect)
    b = centre_rect + 0.5 * np.asarray(fr.road.plane[:3])
    return any(segment_hits_box(a, b, box) for box in fr.boxes)


def unlabelled_high(fr):
    """The scan's points more than 0.3 m above the road outside every labelled box (grown by 0.2 m:
    the points on its faces), once per frame: what may shadow a spot besides the labelled objects."""
    if getattr(fr, "_unlabelled_high", None) is None:
        high = fr.scan_height > 0.3
        for _, h, w, l, loc, ry in fr.boxes:
            high &= ~lidar.in_box(fr.scan_rect, (h + 0.2, w + 0.4, l + 0.4, *loc, ry))
        fr._unlabelled_high = fr.scan[high, :3]
    return fr._unlabelled_high


def support_ok(fr, poly_world, centre_rect, min_ground):
    """LiDAR check of a footprint: (ok, ground count, obstacle count); ok without a scan.  The spot
    must also be in the sensor's view (lidar.visible_ground: no nearer object above the road in its
    direction), so nothing is placed inside another object's LiDAR shadow -- unless the shadow is a
    labelled box's: then the cyclist is hidden behind it in the image too, and labelled occluded (the
    box occludes it), and only the obstacle test applies (the road there is the plane's, unseen), with
    the view test on the unlabelled points alone (nothing unlabelled, a wall, stands in front either)."""
    if fr.scan is None:
        return True, None, None
    shadowed_by_label = behind_label(fr, centre_rect)
    rect = fr.road.to_rect(np.column_stack([poly_world[:, 0], np.zeros(len(poly_world)), poly_world[:, 1]]))
    # only the points near the footprint can count (ground_support's margin is 0.5 m): the same counts
    lo, hi = rect[:, [0, 2]].min(0) - 1.0, rect[:, [0, 2]].max(0) + 1.0
    xz = fr.scan_rect[:, [0, 2]]
    near = ((xz >= lo) & (xz <= hi)).all(1)
    s = lidar.ground_support(fr.scan[near, :3], fr.T_velo_to_rect, fr.road.plane, rect[:, [0, 2]])
    if shadowed_by_label:  # the labelled box may hide the spot, nothing unlabelled may (a wall behind a pedestrian)
        ok = s["obstacle"] == 0 and bool(lidar.visible_ground(unlabelled_high(fr), fr.T_velo_to_rect, fr.road.plane,
                                                                  centre_rect[None])[0])
        return ok, int(s["ground"]), int(s["obstacle"])
    ok = s["ground"] >= min_ground and s["obstacle"] == 0
    if ok:  # only points above the road can block the view (visible_ground's own rule, min_height_m 0.3)
        high = fr.scan[fr.scan_height > 0.3, :3]
        ok = bool(lidar.visible_ground(high, fr.T_velo_to_rect, fr.road.plane, centre_rect[None])[0])
    return ok, int(s["ground"]), int(s["obstacle"])


def draw_frame(cfg, rng, index):
    """-> (instances [{"kind", "bike", "rider", "pose"}], dropped, camera record)."""
    s, ins = cfg.street, cfg.insert
    fid = source.frame_id(cfg, index)
    fr = source.frame(cfg, fid)
    road = fr.road
    axis, axis_src = road_axis(fr.labels, road, s.road_heading_deg)
    boxes = [footprint(b, road, ins.box_margin_m) for b in fr.boxes]
    n_cyc = _count(rng, s.cyclists) if cfg.riders else 0
    n_park = _count(rng, s.parked_bikes)
    placed, out, dropped, checks = [], [], 0, []
    cars = [b for b in fr.boxes if b[0] in CARS]
    for kind in ["cyclist"] * n_cyc + ["parked"] * n_park:
        bike = cfg.bikes[int(rng.integers(len(cfg.bikes)))]
        rider = cfg.riders[int(rng.integers(len(cfg.riders)))] if kind == "cyclist" else None
        pose = {k: float(rng.uniform(*getattr(cfg.pose, k))) for k in POSE_FIELDS if k not in PLACED}
        pose["theta_z_deg"] = 0.0  # no pitch: both tyres on the plane
        if kind == "parked":
            pose["theta_s_deg"] = float(rng.uniform(*s.parked_steer_deg))
        got = None
        behind = bool(cars) and rng.uniform() < ins.behind_cars_share
        for _ in range(int(s.max_tries)):
            z = float(rng.uniform(*s.distance_m))
            u = float(rng.uniform(-s.border_margin, 1.0 + s.border_margin)) * fr.width
            if behind:  # just beyond a labelled car, seen past or over it (replaces z and u)
                _, _, cw, cl, cloc, _ = cars[int(rng.integers(len(cars)))]
                ray = np.array([cloc[0], cloc[2]]) / max(np.hypot(cloc[0], cloc[2]), 1e-6)
                side = np.array([ray[1], -ray[0]])
                xz = np.array([cloc[0], cloc[2]]) + ray * (0.5 * np.hypot(cw, cl) + rng.uniform(0.8, 3.0)) \
                    + side * rng.uniform(-1, 1) * 0.5 * max(cw, cl)
                z = float(xz[1])
                u = float(road.project_rect(np.array([[xz[0], 0.0, xz[1]]]))[0][0, 0])
                if not s.distance_m[0] <= z <= s.distance_m[1]:
                    continue
            if s.heading == "uniform":
                yaw = float(rng.uniform(-180.0, 180.0))
            else:
                yaw = axis + float(rng.uniform(-1, 1)) * s.heading_spread_deg
                if rng.uniform() < s.oncoming_share:
                    yaw += 180.0
            yaw = (yaw + 180.0) % 360.0 - 180.0
            p = spot(road, z, u)
            w = road.to_world(p[None])[0]
            if not s.lateral_m[0] <= w[0] <= s.lateral_m[1]:
                continue
            top = road.to_rect(np.array([[w[0], HEIGHT, w[2]]]))
            (_, vt), zt = road.project_rect(top)[0][0], road.project_rect(top)[1][0]
            if not (zt > 0.5 and vt < fr.height):
                continue
            poly = rectangle(w[0], w[2], yaw, FOOT_L, FOOT_W)
            if any(convex_overlap(poly, b) for b in boxes) or any(convex_overlap(poly, q) for q in placed):
                continue
            ok, ground, obstacle = support_ok(fr, poly, p, ins.min_ground_points)
            if not ok:
                continue
            got = (float(w[0]), float(w[2]), yaw, ground, obstacle)
            break
        if got is None:
            dropped += 1
            continue
        placed.append(rectangle(got[0], got[1], got[2], FOOT_L, FOOT_W))
        pose.update(theta_y_deg=got[2], t_x_m=got[0], t_y_m=0.0, t_z_m=got[1])
        out.append({"kind": kind, "bike": bike, "rider": rider, "pose": [pose[k] for k in POSE_FIELDS]})
        checks.append({"behind_car": behind, "lidar_ground_points": got[3], "lidar_obstacle_points": got[4]})
    camera = {"preset": "frame", "frame": fid, "plane": [round(x, 6) for x in road.plane],
              "plane_source": fr.plane_source, "road_heading_deg": round(axis, 3), "road_heading_source": axis_src,
              "lidar": fr.scan is not None, "placement_checks": checks}
    return out, dropped, camera

"""Sequences in a real KITTI frame (docs/sequences.md, "In KITTI frames"): the frame is the world,
standing still (one instant: the ego camera does not move), and cyclists ride through it on its road
plane under the frames mode's placement rules, checked along the whole trajectory.

Sequence s uses the folder's frames in turn (frame s mod their number).  draw.draw_sequence draws
as for a street sequence and asks FrameWorld where instances may be:
- spot: a depth (uniform in `street.distance_m`) and an image column, the road point seen there
  (frames.placement.spot), as in a still frames sample;
- usable: within `street.lateral_m` and its 1.8 m height projects into the image;
- headings along the road axis of the frame's labelled cars (frames.road.road_axis);
- track_ok: at EVERY frame the footprint (1.9 x 0.8 m along the heading) overlaps no labelled box's
  footprint grown by `insert.box_margin_m` and holds no LiDAR point 0.3-2.5 m above the road; and at
  the frames where the cyclist is in the camera's view within `street.distance_m` (where the scan's
  road coverage is dense enough to ask it), positions at least SPACING_M apart, the LiDAR rules of a
  still (frames.placement.support_ok: seen road under it, not in an unlabelled object's shadow).

The frame's own labelled objects become static tracks of the tracking files (frame_rows).
"""
import math

import numpy as np

from splatting.dataset.frames import placement, source
from splatting.dataset.frames.lidar import OBSTACLE_M
from splatting.dataset.frames.placement import FOOT_L, FOOT_W, HEIGHT
from splatting.dataset.frames.road import convex_overlap, footprint, rectangle, road_axis
from splatting.dataset.sequences.writers import KITTI_TYPES_MOT

SPACING_M = 0.5           # LiDAR support checked at positions this far apart along a track
FOOT_R = 0.5 * math.hypot(FOOT_L, FOOT_W)


class FrameWorld:
    """draw.draw_sequence's world for mode frames (see the module docstring)."""

    def __init__(self, cfg, seq, t):
        self.cfg, st, ins = cfg, cfg.street, cfg.insert
        self.fid = source.frame_id(cfg, seq)
        self.fr = fr = source.frame(cfg, self.fid)
        self.road = fr.road
        self.axis_deg, self.axis_src = road_axis(fr.labels, fr.road, st.road_heading_deg)
        self.ego_speed, self.ego_z, self.spec = 0.0, np.zeros(len(t)), None
        self.boxes = [footprint(b, fr.road, ins.box_margin_m) for b in fr.boxes]
        self.box_discs = [(p.mean(0), float(np.max(np.linalg.norm(p - p.mean(0), axis=1)))) for p in self.boxes]
        if fr.scan is not None:
            h = fr.scan_height
            high = (h > OBSTACLE_M[0]) & (h < OBSTACLE_M[1])
            self.obstacles = fr.road.to_world(fr.scan_rect[high])[:, [0, 2]]
        self.spot_rect = None

    def spot(self, rng):
        st = self.cfg.street
        z = float(rng.uniform(*st.distance_m))
        u = float(rng.uniform(-st.border_margin, 1.0 + st.border_margin)) * self.fr.width
        self.spot_rect = placement.spot(self.road, z, u)
        w = self.road.to_world(self.spot_rect[None])[0]
        return float(w[0]), float(w[2])

    def usable(self, x, z):
        lo, hi = self.cfg.street.lateral_m
        if not lo <= x <= hi:
            return False
        uv, zc = self.road.project_rect(self.road.to_rect(np.array([[x, HEIGHT, z]])))
        return bool(zc[0] > 0.5 and uv[0, 1] < self.fr.height)

    # ------------------------------------------------------------------ the whole trajectory
    def track_ok(self, kind, pose):
        """(ok, record) of a track: poses (n, 8) in the world (docs above)."""
        xz, yaw = np.asarray(pose)[:, [5, 7]], np.asarray(pose)[:, 3]
        uniq = np.unique(np.round(np.column_stack([xz, yaw]), 4), axis=0, return_index=True)[1]
        uniq.sort()
        for poly, (c, r) in zip(self.boxes, self.box_discs):
            near = uniq[np.hypot(*(xz[uniq] - c).T) < r + FOOT_R]
            if any(convex_overlap(rectangle(xz[i, 0], xz[i, 1], yaw[i], FOOT_L, FOOT_W), poly) for i in near):
                return False, None
        fr = self.fr
        if fr.scan is None:
            return True, {"lidar_checked_frames": 0}
        if self._obstacle_hit(xz[uniq], yaw[uniq]):
            return False, None
        ground, checked = [], 0
        for i in self._in_view(xz, yaw):
            poly = rectangle(xz[i, 0], xz[i, 1], yaw[i], FOOT_L, FOOT_W)
            centre = self.road.to_rect(np.array([[xz[i, 0], 0.0, xz[i, 1]]]))[0]
            ok, g, _ = placement.support_ok(fr, poly, centre, self.cfg.insert.min_ground_points)
            if not ok:
                return False, None
            ground.append(g)
            checked += 1
        return True, {"lidar_checked_frames": checked, "lidar_min_ground_points": min(ground) if ground else None}

    def _obstacle_hit(self, xz, yaw):
        """True when a scan point 0.3-2.5 m above the road lies inside any of the footprints."""
        lo, hi = xz.min(0) - FOOT_R, xz.max(0) + FOOT_R
        q = self.obstacles[((self.obstacles >= lo) & (self.obstacles <= hi)).all(1)]
        if not len(q):
            return False
        a = np.radians(yaw)
        f = np.column_stack([np.cos(a), -np.sin(a)])  # the heading on the road (X, Z), as rectangle()
        for k in range(0, len(xz), 64):  # (frames x points) blocks
            d = q[None] - xz[k:k + 64, None]
            fk = f[k:k + 64, None]
            along = d[..., 0] * fk[..., 0] + d[..., 1] * fk[..., 1]
            across = d[..., 0] * fk[..., 1] - d[..., 1] * fk[..., 0]
            if ((np.abs(along) <= FOOT_L / 2) & (np.abs(across) <= FOOT_W / 2)).any():
                return True
        return False

    def _in_view(self, xz, yaw):
        """Frame indices where the footprint's centre is seen in the image (widened by border_margin)
        within street.distance_m, spaced at least SPACING_M apart (or turned 10 degrees)."""
        st = self.cfg.street
        rect = self.road.to_rect(np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]]))
        uv, zc = self.road.project_rect(rect)
        m = st.border_margin * self.fr.width
        seen = (zc > 0.5) & (zc <= st.distance_m[1]) & (uv[:, 0] >= -m) & (uv[:, 0] <= self.fr.width + m)
        out, last = [], None
        for i in np.flatnonzero(seen):
            if last is None or np.hypot(*(xz[i] - xz[last])) >= SPACING_M or abs(yaw[i] - yaw[last]) >= 10.0:
                out.append(int(i))
                last = i
        return out

    # ------------------------------------------------------------------ records
    def camera(self, checks):
        fr = self.fr
        return {"preset": "frame", "frame": self.fid, "plane": [round(x, 6) for x in self.road.plane],
                "plane_source": fr.plane_source, "road_heading_deg": round(self.axis_deg, 3),
                "road_heading_source": self.axis_src, "lidar": fr.scan is not None, "placement_checks": checks}

    def background(self, rng):
        return {"kind": "frame", "frame": self.fid}

    def look_feet(self, poses):
        """Road spots (X, Z) the sequence's light gain is measured around: every track's positions
        SPACING_M apart (frames.sample.FrameSample.road_mask grows each by 1.5 m)."""
        out = []
        for p in poses:
            last = None
            for x, z in np.asarray(p)[:, [5, 7]]:
                if last is None or math.hypot(x - last[0], z - last[1]) >= 1.0:
                    out.append((float(x), float(z)))
                    last = (x, z)
        return out


def frame_rows(frame_lines, first_track):
    """The frame's own label_2 lines (occlusion raised by this frame's cyclists) as tracking rows:
    -> (kitti [(track_id, object dict)], mot [(track_id, row)]).  Objects keep their label order and
    take track ids first_track, first_track + 1, ... (DontCare: -1, KITTI tracking's, and no MOT row)."""
    from cyclist_formats.kitti_frame import IGNORED_TYPE, parse_label_line
    kit, mot, k = [], [], first_track
    for line in frame_lines:
        o = parse_label_line(line)
        if o["type"] == IGNORED_TYPE:
            kit.append([-1, o])
            continue
        kit.append([k, o])
        mot.append([k, {"box": [o["x1"], o["y1"], o["x2"] - o["x1"], o["y2"] - o["y1"]], "kind": "frame",
                        "class": KITTI_TYPES_MOT.get(o["type"], 8), "visibility": -1.0}])
        k += 1
    return kit, mot

"""A KITTI frame's road and camera as the street machinery's world: the road is the plane Y = 0.

Frames:
- rect: KITTI's rectified camera-0 frame (x right, y down, z forward; labels and planes live here).
- camera 2 (image_2): rect + t with t = K^-1 P2[:, 3] (cyclist_formats.kitti_frame.camera_of_P):
  P2 is K [I | t], not K [I | 0]: camera 2 stands ~6 cm left of camera 0, so projecting a rect point
  with K alone would put it ~0.06 fx / z pixels off (1.4 px at 30 m for KITTI's fx = 721).  The
  renderer's camera is (K, R, T) with x_cam2 = R X + T; depths of the labels stay rect z (KITTI's),
  the rendered depth is camera-2 z (they differ by t_z, millimetres).
- world (the street's, docs/street_scenes.md): origin = the foot of camera 0 on the road plane,
  Y = the plane's upward unit normal, Z = rect z projected on the plane (forward), X = Y x Z (left).
  So rect = O + M world with M = [X Y Z] (columns, in rect coordinates), and the renderer's camera
  is R = M, T = O + t.  A bike posed in the world with t_Y = 0 and no pitch (theta_z = 0) stands
  with both tyres on the road plane whatever the plane's tilt: its up axis is the plane's normal.
"""
import math

import numpy as np

from cyclist_formats.kitti_frame import IGNORED_TYPE, camera_of_P
from splatting.dataset.kitti import corners, wrap

CARS = ("Car", "Van", "Truck", "Tram")


class Road:
    """plane (a, b, c, d): unit normal pointing up (b < 0), rect coordinates."""

    def __init__(self, plane, P2, width, height):
        n = np.asarray(plane[:3], float)
        n = n / np.linalg.norm(n)
        self.plane = (float(n[0]), float(n[1]), float(n[2]), float(plane[3]) / float(np.linalg.norm(plane[:3])))
        self.origin = -self.plane[3] * n
        z = np.array([0.0, 0.0, 1.0]) - n[2] * n
        z /= np.linalg.norm(z)
        self.M = np.column_stack([np.cross(n, z), n, z])
        self.K, self.t = camera_of_P(P2)
        self.P2 = np.asarray(P2, float)
        self.width, self.height = int(width), int(height)

    # rect <-> world -------------------------------------------------------
    def to_rect(self, pts_world):
        return np.asarray(pts_world, float) @ self.M.T + self.origin

    def to_world(self, pts_rect):
        return (np.asarray(pts_rect, float) - self.origin) @ self.M

    def camera_pose(self):
        """(R, T): world -> camera 2."""
        return self.M.copy(), self.origin + self.t

    def camera(self):
        from splatting.raster.camera import from_numpy
        R, T = self.camera_pose()
        return from_numpy(self.K, R, T, self.width, self.height)

    def project_rect(self, pts_rect):
        """(n, 3) rect -> (uv (n, 2), camera-2 z (n,)) with P2 (pixel centres at +0.5 as KITTI's)."""
        p = np.asarray(pts_rect, float) @ self.P2[:, :3].T + self.P2[:, 3]
        z = p[:, 2]
        zs = np.where(np.abs(z) > 1e-9, z, 1e-9)
        return p[:, :2] / zs[:, None], z

    def height(self, pts_rect):
        """Signed height above the road plane (m) of rect points (a x + b y + c z + d with the unit
        normal pointing up: the camera is d above the road)."""
        a, b, c, d = self.plane
        return np.asarray(pts_rect, float) @ [a, b, c] + d

    # headings ---------------------------------------------------------------
    def heading_of_ry(self, ry):
        """World theta_y (deg) of a bike facing KITTI rotation_y ry (0 = rect +x)."""
        d = self.M.T @ np.array([math.cos(ry), 0.0, -math.sin(ry)])
        return math.degrees(math.atan2(-d[2], d[0]))

    def ry_of_heading(self, theta_y_deg):
        """KITTI rotation_y of a bike at world heading theta_y (forward (cos t, 0, -sin t))."""
        a = math.radians(theta_y_deg)
        d = self.M @ np.array([math.cos(a), 0.0, -math.sin(a)])
        return math.atan2(-d[2], d[0])

    def box3d(self, box):
        """An extent_box (world bottom centre, heading_deg, h, w, l) -> KITTI (location (3,), ry, alpha):
        the bottom centre in rect coordinates, rotation_y about rect y, alpha = ry - atan2(x, z)."""
        loc = self.to_rect(np.asarray(box["bottom_centre"], float)[None])[0]
        ry = wrap(self.ry_of_heading(box["heading_deg"]))
        return loc, ry, wrap(ry - math.atan2(loc[0], loc[2]))


def boxes_of(labels):
    """The labelled 3D boxes of a frame: [(type, h, w, l, (x, y, z), ry)] (DontCare left out)."""
    out = []
    for row, _ in labels:
        if row["type"] == IGNORED_TYPE or min(row["h"], row["w"], row["l"]) <= 0:
            continue
        out.append((row["type"], row["h"], row["w"], row["l"], (row["x"], row["y"], row["z"]), row["rotation_y"]))
    return out


def footprint(box, road, margin=0.0):
    """A labelled box's footprint on the road: (4, 2) world (X, Z) corners, grown by margin (m)."""
    _, h, w, l, loc, ry = box
    c = corners(h, l=l + 2 * margin, w=w + 2 * margin, loc=loc, ry=ry)[:, :4].T  # the bottom face
    return road.to_world(c)[:, [0, 2]]


def rectangle(x, z, theta_y_deg, length, width):
    """(4, 2) world (X, Z) corners of a length x width rectangle centred at (x, z) facing theta_y."""
    a = math.radians(theta_y_deg)
    f = np.array([math.cos(a), -math.sin(a)])
    s = np.array([f[1], -f[0]])
    c = np.array([x, z])
    return np.array([c + f * length / 2 + s * width / 2, c + f * length / 2 - s * width / 2,
                     c - f * length / 2 - s * width / 2, c - f * length / 2 + s * width / 2])


def segment_hits_box(a, b, box, grow=0.0):
    """True when the rect segment a -> b passes through a labelled box (type, h, w, l, loc, ry) grown
    by `grow` metres (slab test in the box's frame)."""
    _, h, w, l, loc, ry = box
    co, si = math.cos(ry), math.sin(ry)
    Ry = np.array([[co, 0, si], [0, 1, 0], [-si, 0, co]])
    c = np.asarray(loc, float) + [0.0, -h / 2, 0.0]
    o = Ry.T @ (np.asarray(a, float) - c)
    d = Ry.T @ (np.asarray(b, float) - np.asarray(a, float))
    half = np.array([l / 2, h / 2, w / 2]) + grow
    t0, t1 = 0.0, 1.0
    for k in range(3):
        if abs(d[k]) < 1e-12:
            if abs(o[k]) > half[k]:
                return False
            continue
        ta, tb = sorted(((-half[k] - o[k]) / d[k], (half[k] - o[k]) / d[k]))
        t0, t1 = max(t0, ta), min(t1, tb)
        if t0 > t1:
            return False
    return True


def convex_overlap(a, b):
    """True when two convex polygons (n, 2) overlap (separating axis test; touching = apart)."""
    for poly in (a, b):
        e = np.roll(poly, -1, 0) - poly
        for nx, ny in np.column_stack([-e[:, 1], e[:, 0]]):
            pa, pb = a @ [nx, ny], b @ [nx, ny]
            if pa.max() <= pb.min() or pb.max() <= pa.min():
                return False
    return True


def road_axis(labels, road, fallback_deg):
    """World theta_y (deg) of riding along the road, away from the camera: the dominant direction of
    the labelled cars (their rotation_y as an axis, averaged on the doubled angle so that cars both
    ways agree), else the config's street.road_heading_deg (0 = along the camera's axis); -> (deg,
    source)."""
    rys = [row["rotation_y"] for row, _ in labels if row["type"] in CARS]
    if rys:
        th = [math.radians(road.heading_of_ry(r)) for r in rys]
        ax = 0.5 * math.atan2(sum(math.sin(2 * t) for t in th), sum(math.cos(2 * t) for t in th))
        deg = math.degrees(ax)
        # of the axis' two directions, the one riding away from the camera (world +Z: forward -sin t > 0)
        if -math.sin(ax) < 0:
            deg += 180.0
        return (deg + 180.0) % 360.0 - 180.0, "cars"
    return float(fallback_deg) - 90.0, "config"

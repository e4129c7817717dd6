"""What generate.make_sample does differently for a frames-mode sample: the frame's camera and image,
its depth as an occluder, the look matching, the KITTI rows of the frame itself, the shadows' sun.

One FrameSample per sample, built from the draw (generate.draw -> placement.draw_frame).
"""
import math

import numpy as np
import torch

from cyclist_formats import kitti_frame
from splatting.bike.pose import transform_gaussians
from splatting.dataset.frames import lidar, look, occlusion, source
from splatting.dataset.frames.scan_insert import insert_into_scan
from splatting.relight.shading import Light, sun_direction


GROUND_M = 0.2  # scan points this close to the road plane are road (lidar.ground_support's tolerance is 0.15)


class FrameSample:
    def __init__(self, cfg, d, index):
        self.cfg, self.index, self.d = cfg, index, d
        self.frame = source.frame(cfg, d["camera"]["frame"])
        self.road = self.frame.road
        self.ins = cfg.insert
        self._boxes = None
        self.hidden_px = 0

    def camera(self):
        return self.road.camera()

    def image(self):
        return self.frame.image()

    def box3d(self, box):
        return self.road.box3d(box)

    def sun(self):
        """The cast shadows' sun (world frame): the config's elevation and azimuth (0 = world +X)."""
        lk = self.ins.look
        return Light(sun_direction=sun_direction(lk.sun_elevation_deg, lk.sun_azimuth_deg))

    def boxes(self):
        if self._boxes is None:
            fr = self.frame
            self._boxes = occlusion.boxes_depth(self.road, fr.boxes, fr.width, fr.height)
        return self._boxes

    def depth(self, box=None):
        """The frame's depth (H, W) camera-2 z, 0 unknown: labelled boxes and LiDAR, the nearer.  The
        LiDAR's only inside box (u0, v0, w, h) grown by 16 px when given (where cyclists were drawn):
        the image is densified there alone, through P2 shifted to the crop."""
        fr = self.frame
        D = self.boxes()[0].copy() if self.ins.box_occluders else np.zeros((fr.height, fr.width), np.float32)
        if fr.scan is not None and box is not None:  # the road's own points never hide what stands on it: left out
            pad = 16
            u0, v0 = max(box[0] - pad, 0), max(box[1] - pad, 0)
            u1, v1 = min(box[0] + box[2] + pad, fr.width), min(box[1] + box[3] + pad, fr.height)
            P = fr.calib["P2"].copy()
            P[0] -= u0 * P[2]
            P[1] -= v0 * P[2]
            pts = fr.scan[fr.scan_height > GROUND_M, :3]
            Dl = lidar.lidar_depth_image(pts, fr.T_velo_to_rect, P, u1 - u0, v1 - v0)
            Dl = np.where(Dl > 0, Dl + self.road.t[2], 0.0).astype(np.float32)  # rect z -> camera-2 z
            D[v0:v1, u0:u1] = occlusion.nearer(D[v0:v1, u0:u1], Dl)
        return D

    def occlude(self, L, box):
        """Hide inserted pixels behind the frame; -> (keypoint alpha, keypoint depth)."""
        ka, kd, hidden = occlusion.occlude(L, self.depth(box), self.ins.occlusion_margin_m)
        self.hidden_px = int(hidden.sum())
        return ka, kd

    def composite(self, L, box, feet_world):
        """The output image: the frame with the inserted layers, light, blur and noise matched."""
        fr, lk = self.frame, self.ins.look
        img = self.image()
        rec = {"hidden_px": self.hidden_px}
        gain, sigma, noise = np.ones(3), 0.0, 0.0
        if lk.match:  # (a sequence measures its one gain around all its tracks: no flicker as they move)
            gain, road_rgb = look.road_gain(img, self.road_mask(self.d.get("look_feet_world", feet_world)))
            est = self.frame.stat("blur", look.estimate_blur)
            own = None
            if lk.blur_sigma_px == "auto":
                own = look.render_blur(L, box)
                sigma = 0.0 if est is None else math.sqrt(max(est ** 2 - (own or 0.0) ** 2, 0.0))
            else:
                sigma = float(lk.blur_sigma_px)
            noise = self.frame.stat("noise", look.estimate_noise) if lk.noise_sigma == "auto" else float(lk.noise_sigma)
            rec.update(road_rgb=road_rgb, frame_blur_px=None if est is None else round(est, 4),
                       render_blur_px=None if own is None else round(own, 4))
        rec.update(gain=[round(float(x), 4) for x in gain], blur_sigma_px=round(float(sigma), 4),
                   noise_sigma=round(float(noise), 5))
        rng = np.random.default_rng([self.cfg.seed, self.index, 26])
        out, changed = look.composite(img, L, box, gain, round(float(sigma), 4), round(float(noise), 5), rng)
        self.changed = changed
        return out, rec

    def road_mask(self, feet_world):
        """Road pixels near the inserted instances: their footprints grown by 1.5 m (a square in the
        world X, Z), projected, below the horizon, outside every labelled box's 2D box."""
        fr = self.frame
        m = np.zeros((fr.height, fr.width), bool)
        for x, z in feet_world:
            sq = np.array([[x - 1.5, 0, z - 1.5], [x + 1.5, 0, z - 1.5], [x + 1.5, 0, z + 1.5], [x - 1.5, 0, z + 1.5]])
            uv, zc = self.road.project_rect(self.road.to_rect(sq))
            if (zc <= 0.5).any():
                continue
            u0, v0 = max(int(uv[:, 0].min()), 0), max(int(uv[:, 1].min()), 0)
            u1, v1 = min(int(uv[:, 0].max()) + 1, fr.width), min(int(uv[:, 1].max()) + 1, fr.height)
            if u1 > u0 and v1 > v0:
                m[v0:v1, u0:u1] = True
        for row, _ in fr.labels:
            m[max(int(row["y1"]), 0):int(row["y2"]) + 1, max(int(row["x1"]), 0):int(row["x2"]) + 1] = False
        return m

    def frame_rows(self, L):
        """The frame's own label_2 lines with raised occlusion -> ([text], [(old, new, share)])."""
        fr = self.frame
        per = self.boxes()[1]
        idx, k = [], 0
        for row, _ in fr.labels:  # boxes_of keeps the rows with a box, in order
            if row["type"] == kitti_frame.IGNORED_TYPE or min(row["h"], row["w"], row["l"]) <= 0:
                idx.append(None)
            else:
                idx.append(k)
                k += 1
        res = occlusion.raised_occlusion(fr.labels, per, idx, L["label"], L["depth"], fr.width, fr.height)
        lines = [text if new == old else kitti_frame.with_occluded(text, new) for (_, text), (old, new, _) in zip(fr.labels, res)]
        return lines, res

    def kitti_extras(self, L):
        lines, res = self.frame_rows(L)
        fr = self.frame
        return {"frame_lines": lines, "frame_id": fr.id, "folder": fr.folder, "plane": self.road.plane,
                "occlusion_raised": res, "scan": None}

    def insert_scan(self, posed, extras):
        """The frame's scan with the inserted instances ray-cast into it (lidar.insert_into_scan);
        posed: [(world Gaussians, eps2d, antialiased)] of the full models.  Sets extras["frame"]["scan"]
        and returns the points on each instance (None without a scan)."""
        fr = self.frame
        if fr.scan is None or not posed:
            return None
        H = np.eye(4)
        H[:3, :3], H[:3, 3] = self.road.M, self.road.origin  # world -> rect
        Ht = torch.from_numpy(H)
        gs = [transform_gaussians(g, Ht) for g, _, _ in posed]
        rng = np.random.default_rng([self.cfg.seed, self.index, 64])
        new, counts, removed = insert_into_scan(fr.scan, fr.T_velo_to_rect, gs, eps2d=[e for _, e, _ in posed],
                                                antialiased=[a for _, _, a in posed], rng=rng)
        extras["frame"]["scan"] = new
        self.scan_record = {"points_in": int(len(fr.scan)), "points_out": int(len(new)), "removed": int(removed.sum())}
        return counts

    def record(self):
        fr = self.frame
        return {"frame": fr.id, "width": fr.width, "height": fr.height, "plane": list(self.road.plane),
                "plane_source": fr.plane_source, "lidar": fr.scan is not None}

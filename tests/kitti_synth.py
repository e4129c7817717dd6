"""A small synthetic KITTI object folder for the frames tests (no KITTI data is committed).

Camera 0 at the rectified origin, 1.65 m above a flat road (plane 0 x - 1 y + 0 z + 1.65 = 0);
camera 2 (image_2) 6 cm to its left as in KITTI (P2[0, 3] = 0.06 fx).  The Velodyne sits 0.08 m
above and 0.27 m behind camera 0 with KITTI's axes (x forward, y left, z up), so
Tr_velo_to_cam = [[0, -1, 0, 0], [0, 0, -1, -0.08], [1, 0, 0, -0.27]] and R0_rect = I.
"""
import os

import numpy as np

W, H = 400, 128
FX = FY = 200.0
CX, CY = 200.0, 60.0
TX = 0.06  # camera 2 stands 6 cm left of camera 0: P2[0, 3] = fx * 0.06
CAM_H = 1.65
TR_VELO = np.array([[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, -0.08], [1.0, 0.0, 0.0, -0.27]])


def P2():
    return np.array([[FX, 0.0, CX, FX * TX], [0.0, FY, CY, 0.0], [0.0, 0.0, 1.0, 0.0]])


def calib_text():
    P0 = np.array([[FX, 0.0, CX, 0.0], [0.0, FY, CY, 0.0], [0.0, 0.0, 1.0, 0.0]])
    rows = {"P0": P0, "P1": P0 - np.array([[0, 0, 0, FX * 0.54], [0, 0, 0, 0], [0, 0, 0, 0]]), "P2": P2(),
            "P3": P0 - np.array([[0, 0, 0, FX * 0.48], [0, 0, 0, 0], [0, 0, 0, 0]]), "R0_rect": np.eye(3),
            "Tr_velo_to_cam": TR_VELO, "Tr_imu_to_velo": np.column_stack([np.eye(3), [-0.81, 0.32, -0.8]])}
    return "".join(f"{k}: " + " ".join(f"{v:.12e}" for v in m.ravel()) + "\n" for k, m in rows.items())


def image(seed=0):
    """Sky above the horizon, a grey textured road below, a little sensor noise."""
    rng = np.random.default_rng(seed)
    img = np.zeros((H, W, 3), np.float64)
    v = np.arange(H)[:, None]
    img[:] = np.where(v[..., None] < CY, [150, 170, 200], [95, 92, 90])
    img += rng.normal(0, 2.0, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def box_row(kind, h, w, l, x, y, z, ry, occluded=0):
    """A label_2 row of a 3D box with its 2D box from the projection (the devkit's corners)."""
    from splatting.dataset.kitti import corners, project_rect, wrap
    c = corners(h, w, l, (x, y, z), ry)
    uv = project_rect(P2(), c)
    x1, y1 = max(0.0, uv[0].min()), max(0.0, uv[1].min())
    x2, y2 = min(W - 1.0, uv[0].max()), min(H - 1.0, uv[1].max())
    alpha = wrap(ry - np.arctan2(x, z))
    return (f"{kind} 0.00 {occluded} {alpha:.2f} {x1:.2f} {y1:.2f} {x2:.2f} {y2:.2f} {h:.2f} {w:.2f} {l:.2f} "
            f"{x:.2f} {y:.2f} {z:.2f} {ry:.2f}")


def scan(labels=(), seed=0):
    """A Velodyne-frame scan: road points on a grid (0.25 m) from 2 to 40 m, and points on the
    faces of each labelled box (rect (h, w, l, x, y, z, ry))."""
    rng = np.random.default_rng(seed)
    xs, zs = np.meshgrid(np.arange(-10, 10, 0.25), np.arange(2, 40, 0.25))
    road = np.column_stack([xs.ravel(), np.full(xs.size, CAM_H), zs.ravel()])
    pts = [road]
    for h, w, l, x, y, z, ry in labels:
        u = rng.uniform(-0.5, 0.5, (3000, 3))
        u[np.arange(3000), rng.integers(0, 3, 3000)] = rng.choice([-0.5, 0.5], 3000)  # on a face
        loc = np.stack([u[:, 0] * l, -(u[:, 1] + 0.5) * h, u[:, 2] * w], 1)
        c, s = np.cos(ry), np.sin(ry)
        R = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        pts.append(loc @ R.T + [x, y, z])
    rect = np.concatenate(pts)
    T = np.eye(4)
    T[:3] = TR_VELO
    velo = (np.linalg.inv(T) @ np.column_stack([rect, np.ones(len(rect))]).T).T[:, :3]
    return np.column_stack([velo, np.full(len(velo), 0.3)]).astype(np.float32)


def write_frames(root, frames, with_planes=True, with_velodyne=False):
    """frames: {id: [label rows]} -> a KITTI object folder at root (returns root)."""
    from splatting.dataset import png
    for d in ("image_2", "calib", "label_2") + (("planes",) if with_planes else ()) + \
             (("velodyne",) if with_velodyne else ()):
        os.makedirs(os.path.join(root, d), exist_ok=True)
    for k, (fid, rows) in enumerate(frames.items()):
        png.write(os.path.join(root, "image_2", fid + ".png"), image(k), 1)
        with open(os.path.join(root, "calib", fid + ".txt"), "w") as f:
            f.write(calib_text())
        with open(os.path.join(root, "label_2", fid + ".txt"), "w") as f:
            f.write("".join(r + "\n" for r in rows))
        if with_planes:
            with open(os.path.join(root, "planes", fid + ".txt"), "w") as f:
                f.write(f"# Matrix\nWIDTH 4\nHEIGHT 1\n0.000000e+00 -1.000000e+00 0.000000e+00 {CAM_H:.6e} \n")
        if with_velodyne:
            boxes = []
            for r in rows:
                p = r.split()
                if p[0] != "DontCare":
                    boxes.append(tuple(float(x) for x in p[8:15]))
            scan(boxes, k).tofile(os.path.join(root, "velodyne", fid + ".bin"))
    return str(root)


def scan_with_wall(z_wall, wall_h, seed=0):
    """A scan of the road (0.25 m grid, 2-40 m, |x| < 10 m) with an unlabelled wall wall_h high
    across it at depth z_wall, as the sensor sees it: no road points in the wall's shadow (the
    sensor stands 1.73 m above the road, 0.27 m behind camera 0)."""
    rng = np.random.default_rng(seed)
    sy, sz = -0.08, -0.27  # the sensor in rect (Tr_velo_to_cam's translation)
    h_s = CAM_H - sy
    end = sz + (z_wall - sz) * h_s / (h_s - wall_h)  # where the ray over the wall's top meets the road
    xs, zs = np.meshgrid(np.arange(-10, 10, 0.25), np.arange(2, 40, 0.25))
    xs, zs = xs.ravel(), zs.ravel()
    seen = (zs < z_wall) | (zs > end)
    road = np.column_stack([xs[seen], np.full(seen.sum(), CAM_H), zs[seen]])
    wall = np.column_stack([rng.uniform(-10, 10, 4000), CAM_H - rng.uniform(0, wall_h, 4000), np.full(4000, z_wall)])
    rect = np.concatenate([road, wall])
    T = np.eye(4)
    T[:3] = TR_VELO
    velo = (np.linalg.inv(T) @ np.column_stack([rect, np.ones(len(rect))]).T).T[:, :3]
    return np.column_stack([velo, np.full(len(velo), 0.3)]).astype(np.float32), end

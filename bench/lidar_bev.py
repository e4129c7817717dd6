"""The bird's-eye view picture of docs/kitti_lidar.md: a development scan with cyclists inserted
by splatting.dataset.frames.scan_insert, their points coloured, the real points they shadow
marked, and each cyclist's points seen from the sensor (lateral offset x height).

    .venv/bin/python bench/lidar.py --image docs/img/kitti_lidar_bev.png --image-frame 1
"""
import math

import numpy as np

from splatting.dataset.frames import lidar
from splatting.dataset.frames.scan_insert import insert_into_scan

# (x, z, rotation_y) in rect on frame 000001's straight road: riding away on the right, oncoming
# on the left (right-hand traffic), one far
BEV_SPOTS = ((1.8, 9.0, -math.pi / 2), (-2.6, 16.0, math.pi / 2), (1.4, 26.0, -math.pi / 2))
COLOURS = ("#e41a1c", "#ff7f00", "#984ea3")


def _box_bev(g, T):
    """Corners (5, 2) of the Gaussians' means' oriented extent in velo x, y (1st-99th percentile
    along the cyclist's length and width), for drawing."""
    p = lidar.rect_to_velo(g.means.detach().double().numpy(), T)[:, :2]
    c = p.mean(0)
    u, s, vt = np.linalg.svd(p - c, full_matrices=False)
    q = (p - c) @ vt.T
    lo, hi = np.percentile(q, 1, 0), np.percentile(q, 99, 0)
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]], [lo[0], lo[1]]])
    return corners @ vt + c


def draw_bev(frame, cyc, path, spots=BEV_SPOTS, seed=0):
    """Insert the cyclist at spots into the frame's scan and draw the picture to path; returns
    {"counts", "removed", "support": [ground_support per spot], "visible": [...]}."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bench.lidar import posed_in_rect
    from cyclist_formats.atomic import atomic_path

    scan, T = frame["scan"], frame["T"]
    plane = lidar.fit_ground_plane(scan, T, seed)
    gs, eps, aas, support, visible = [], [], [], [], []
    for x, z, ry in spots:
        g, e, aa = posed_in_rect(cyc, plane, x, z, ry)
        gs.append(g)
        eps.append(e)
        aas.append(aa)
        foot = np.array([[x - 0.4, z - 0.9], [x + 0.4, z - 0.9], [x + 0.4, z + 0.9], [x - 0.4, z + 0.9]])
        support.append(lidar.ground_support(scan, T, plane, foot))
        y = -(plane[0] * x + plane[2] * z + plane[3]) / plane[1]
        visible.append(bool(lidar.visible_ground(scan, T, plane, [[x, y, z]])[0]))
    new, counts, removed = insert_into_scan(scan, T, gs, eps2d=eps, antialiased=aas, rng=seed)
    n_real = int((~removed).sum())
    real, added = new[:n_real], new[n_real:]
    owner = np.repeat(np.arange(len(counts)), counts)

    fig = plt.figure(figsize=(12, 7.2), dpi=100)
    ax = fig.add_axes([0.04, 0.07, 0.5, 0.86])
    lim_x, lim_y = (0, 34), (-12, 12)
    view = lambda p: (p[:, 0] > lim_x[0]) & (p[:, 0] < lim_x[1]) & (np.abs(p[:, 1]) < lim_y[1])  # noqa: E731
    r = real[view(real)]
    ax.scatter(-r[:, 1], r[:, 0], s=0.3, c=np.clip(r[:, 2], -2.0, 1.0), cmap="Greys_r", vmin=-3.0, vmax=1.5,
               linewidths=0, rasterized=True)
    sh = scan[removed]
    ax.scatter(-sh[:, 1], sh[:, 0], s=1.5, c="#377eb8", linewidths=0, label=f"shadowed, removed ({len(sh)})")
    for j, col in enumerate(COLOURS[:len(counts)]):
        a = added[owner == j]
        ax.scatter(-a[:, 1], a[:, 0], s=2.5, c=col, linewidths=0, label=f"cyclist {j + 1}: {counts[j]} points")
        b = _box_bev(gs[j], T)
        ax.plot(-b[:, 1], b[:, 0], c=col, lw=0.8)
    ax.set_xlim(-lim_y[1], -lim_y[0])
    ax.set_ylim(*lim_x)
    ax.set_aspect("equal")
    ax.set_xlabel("left - right (m)")
    ax.set_ylabel("forward (m)")
    ax.legend(loc="upper left", fontsize=8, markerscale=4)
    ax.set_title(f"KITTI {frame['name']}: scan with inserted cyclists (bird's-eye view)", fontsize=10)
    # each cyclist from the sensor: azimuth x elevation of its points and the real ones around it
    for j in range(len(counts)):
        axj = fig.add_axes([0.6, 0.07 + (len(counts) - 1 - j) * 0.31, 0.37, 0.26])
        a = added[owner == j]
        c = a[:, :3].mean(0)
        az0 = math.atan2(c[1], c[0])

        def ang(p):
            az = (np.arctan2(p[:, 1], p[:, 0]) - az0 + math.pi) % (2 * math.pi) - math.pi
            return -np.degrees(az), np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])))

        ha, va = ang(a)
        w = max(np.ptp(ha), np.ptp(va) * 1.5) * 0.9 + 0.5
        hr, vr = ang(real)
        near = (np.abs(hr) < w) & (np.abs(vr - va.mean()) < w / 1.6) & (np.linalg.norm(real[:, :3], axis=1) < 80)
        axj.scatter(hr[near], vr[near], s=2, c="#bbbbbb", linewidths=0)
        hs, vs = ang(sh)
        axj.scatter(hs, vs, s=2, c="#377eb8", linewidths=0)
        for k, col in enumerate(COLOURS[:len(counts)]):  # every cyclist: a nearer one may cover this one
            hk, vk = ang(added[owner == k])
            axj.scatter(hk, vk, s=4, c=col, linewidths=0)
        axj.set_xlim(-w, w)
        axj.set_ylim(va.mean() - w / 1.6, va.mean() + w / 1.6)
        axj.set_aspect("equal")
        axj.set_title(f"cyclist {j + 1} ({np.linalg.norm(c):.1f} m) seen from the sensor: azimuth x elevation, deg",
                      fontsize=8, color=COLOURS[j])
        axj.tick_params(labelsize=7)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return {"counts": counts, "removed": int(removed.sum()), "support": support, "visible": visible}

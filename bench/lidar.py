"""LiDAR geometry on the KITTI development frames (docs/kitti_lidar.md); prints one JSON object.

- plane: the RANSAC road plane of every frame's scan against its planes/*.txt (angle between the
  normals, camera height difference, and the largest height difference of the two planes over
  the road 5-40 m ahead, |x| < 10 m), and the fit's time;
- depth: the densified LiDAR depth image's error on held-out points (10 % of each scan's points
  hidden, the image built from the rest, |depth - hidden point's depth| at the pixels that
  only hidden points fall in), and the same for a plain 13 x 5 min filter as the baseline;
- beams: the HDL-64E table and azimuth step estimated from the scans (hdl64.estimate_beams);
- insert: insert_into_scan's time per cyclist on a development scan, with --bike / --avatar (a
  trained bike folder and rider avatar; default: the demo's in out/demo when present).

    .venv/bin/python bench/lidar.py [--frames ../shared/realism/kitti_dev] [--bike DIR --avatar DIR]
        [--image docs/img/kitti_lidar_bev.png]

make bench: run(results, out) adds the summary numbers as lidar_* keys (bench/run.py's stage
contract); skipped without the development frames, insertion timed only when the demo's bike
and rider exist in out/demo.
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from splatting.dataset.frames import hdl64, lidar  # noqa: E402

# the repository's sibling shared/ (main checkout) or the worktrees' grand-parent's one
DEV = next((p for p in (os.path.join(ROOT, "..", "shared", "realism", "kitti_dev"),
                        os.path.join(ROOT, "..", "..", "shared", "realism", "kitti_dev")) if os.path.isdir(p)),
           os.path.join(ROOT, "..", "shared", "realism", "kitti_dev"))


DEMO = os.path.join(ROOT, "out", "demo")  # make demo's bikes and rider
# (x, z, rotation_y) in rect on frame 000001's road: near, middle and far, riding along it
INSERT_SPOTS = ((1.8, 6.0, -math.pi / 2), (-2.6, 12.0, math.pi / 2), (1.4, 20.0, -math.pi / 2),
                (-2.0, 35.0, math.pi / 2))


def read_calib(path):
    """KITTI calib file -> (T_velo_to_rect (4, 4), P2 (3, 4))."""
    c = {}
    with open(path, encoding="utf-8") as f:
        for line in f:
            if ":" in line:
                k, v = line.split(":", 1)
                c[k.strip()] = np.array(v.split(), np.float64)
    R0, Tr = np.eye(4), np.eye(4)
    R0[:3, :3] = c["R0_rect"].reshape(3, 3)
    Tr[:3, :4] = c["Tr_velo_to_cam"].reshape(3, 4)
    return R0 @ Tr, c["P2"].reshape(3, 4)


def read_frame(root, i):
    """One development frame: scan (N, 4) float32, T, P2, plane (4,) from planes/, image size."""
    from PIL import Image

    name = f"{i:06d}"
    T, P2 = read_calib(os.path.join(root, "calib", name + ".txt"))
    scan = np.fromfile(os.path.join(root, "velodyne", name + ".bin"), np.float32).reshape(-1, 4)
    with open(os.path.join(root, "planes", name + ".txt"), encoding="utf-8") as f:
        plane = np.array(f.read().split("\n")[3].split(), np.float64)
    with Image.open(os.path.join(root, "image_2", name + ".png")) as im:
        W, H = im.size
    return {"name": name, "scan": scan, "T": T, "P2": P2, "plane": plane, "width": W, "height": H}


def held_out_depth_error(frame, seed=0, share=0.1):
    """Hide `share` of the scan, densify the rest, compare at the pixels only hidden points hit."""
    rng = np.random.default_rng(seed)
    s, T, P2, W, H = frame["scan"], frame["T"], frame["P2"], frame["width"], frame["height"]
    hide = rng.random(len(s)) < share
    kept = lidar.sparse_depth(*lidar.project_to_image(s[~hide], T, P2, W, H), W, H)
    hidden = lidar.sparse_depth(*lidar.project_to_image(s[hide], T, P2, W, H), W, H)
    t = time.perf_counter()
    dense = lidar.densify_depth(kept, P2[1, 1], P2[1, 2])
    dt = time.perf_counter() - t
    m = (hidden > 0) & (kept == 0)
    got = dense[m] > 0
    err = np.abs(dense[m][got] - hidden[m][got])
    # the baseline: a plain min filter over the same reach (+-6 rows, +-2 columns) of the sparse depth
    base = min_filter_depth(kept)
    bgot = base[m] > 0
    berr = np.abs(base[m][bgot] - hidden[m][bgot])
    return {"pixels": int(m.sum()), "coverage": float(got.mean()), "median_m": float(np.median(err)),
            "p90_m": float(np.percentile(err, 90)), "median_rel": float(np.median(err / hidden[m][got])),
            "densify_s": dt, "minfilter_median_m": float(np.median(berr)),
            "minfilter_p90_m": float(np.percentile(berr, 90)), "minfilter_coverage": float(bgot.mean())}


def min_filter_depth(D, kh=13, kw=5):
    """The nearest depth within a kh x kw window (a max pool of inverse depth), 0 where none."""
    import torch

    inv = torch.from_numpy(np.where(D > 0, 1.0 / np.maximum(D, 1e-6), 0.0).astype(np.float32))
    p = torch.nn.functional.max_pool2d(inv[None, None], (kh, kw), stride=1, padding=(kh // 2, kw // 2))[0, 0].numpy()
    return np.where(p > 0, 1.0 / np.maximum(p, 1e-12), 0.0).astype(np.float32)


def plane_agreement(frame, seed=0):
    t = time.perf_counter()
    p = lidar.fit_ground_plane(frame["scan"], frame["T"], seed)
    dt = time.perf_counter() - t
    q = lidar.normalise_plane(frame["plane"])
    x, z = np.meshgrid(np.linspace(-10, 10, 21), np.linspace(5, 40, 36))
    # the two planes' road heights (rect y) over the grid
    yp = -(p[0] * x + p[2] * z + p[3]) / p[1]
    yq = -(q[0] * x + q[2] * z + q[3]) / q[1]
    return {"angle_deg": math.degrees(math.acos(min(1.0, float(p[:3] @ q[:3])))), "height_diff_m": float(p[3] - q[3]),
            "max_road_diff_m": float(np.abs(yp - yq).max()), "fit_s": dt, "plane": [round(float(v), 5) for v in p]}


def people_reflectance(root, names):
    """Reflectance percentiles of the scan points inside the frames' Pedestrian and Cyclist boxes
    (more than 10 cm above the box bottom: not the road under them)."""
    vals = []
    for n in names:
        f = read_frame(root, int(n))
        rect = lidar.velo_to_rect(f["scan"], f["T"])
        with open(os.path.join(root, "label_2", n + ".txt"), encoding="utf-8") as fh:
            for line in fh:
                t = line.split()
                if t and t[0] in ("Pedestrian", "Cyclist"):
                    box = [float(v) for v in t[8:15]]
                    m = lidar.in_box(rect, box) & (rect[:, 1] < box[4] - 0.1)
                    vals.append(f["scan"][m, 3])
    v = np.concatenate(vals) if vals else np.zeros(0)
    if not len(v):
        return {"points": 0}
    q = np.percentile(v, [10, 25, 50, 75, 90])
    return {"points": int(len(v)), **{f"p{k}": round(float(x), 3) for k, x in zip((10, 25, 50, 75, 90), q)}}


def demo_cyclist(bike, avatar_dir):
    """A Cyclist from a trained bike folder and a rider avatar folder (riders_root/<id>)."""
    from splatting.cyclist.assets import load_avatar, load_bike
    from splatting.cyclist.compose import Cyclist

    av, _ = load_avatar(os.path.basename(os.path.normpath(avatar_dir)), os.path.dirname(os.path.normpath(avatar_dir)),
                        synthetic="never")
    return Cyclist(load_bike(bike, synthetic="never"), av)


def posed_in_rect(cyc, plane, x, z, ry, pedal_deg=30.0):
    """(Gaussians in rect, eps2d, antialiased mask) of the cyclist standing on the plane at
    rect (x, z) with heading ry (KITTI rotation_y)."""
    import torch

    from splatting.bike.pose import transform_gaussians
    from splatting.cyclist.compose import frame_eps2d
    from cyclist_formats.instances import IDS

    fr = cyc.pose(torch.tensor([pedal_deg, 0, 0, 0, 0, 0, 0, 0], dtype=torch.float64))[0]
    g = transform_gaussians(fr.gaussians, torch.as_tensor(lidar.canonical_to_rect(plane, x, z, ry)))
    aa = (fr.ids != IDS["rider"]) & bool(cyc.bike.antialiased)
    return g, frame_eps2d(fr.ids, cyc.bike, cyc.avatar), aa


def insert_timing(frame, cyc, spots, repeats):
    """insert_into_scan on a development scan, one cyclist at each (x, z, ry) spot on the fitted
    road: median seconds per cyclist, points on it, real points removed."""
    from splatting.dataset.frames.scan_insert import insert_into_scan

    plane = lidar.fit_ground_plane(frame["scan"], frame["T"], 0)
    rows = []
    for x, z, ry in spots:
        g, e, aa = posed_in_rect(cyc, plane, x, z, ry)
        ts = []
        for _ in range(repeats):
            t = time.perf_counter()
            _, counts, removed = insert_into_scan(frame["scan"], frame["T"], [g], eps2d=e, antialiased=aa, rng=0)
            ts.append(time.perf_counter() - t)
        rows.append({"x": x, "z": z, "ry": ry, "gaussians": len(g), "seconds": float(np.median(ts)),
                     "points": counts[0], "removed": int(removed.sum())})
    return rows


def frame_names(root):
    return sorted(f[:-4] for f in os.listdir(os.path.join(root, "velodyne")) if f.endswith(".bin"))


def measure(root, bike=None, avatar=None, repeats=3, image=None, image_frame=1):
    """Everything the module docstring lists, as one dict (insertion only with a bike and avatar)."""
    names = frame_names(root)
    frames = [read_frame(root, int(n)) for n in names]
    planes = [dict(frame=f["name"], **plane_agreement(f)) for f in frames]
    depth = [dict(frame=f["name"], **held_out_depth_error(f, seed=k)) for k, f in enumerate(frames)]
    el, step, n = hdl64.estimate_beams([f["scan"] for f in frames])
    med = lambda rows, k: float(np.median([r[k] for r in rows]))  # noqa: E731
    out = {
        "frames": len(frames),
        "plane_angle_deg_median": med(planes, "angle_deg"), "plane_angle_deg_max": max(r["angle_deg"] for r in planes),
        "plane_height_diff_m_median_abs": float(np.median([abs(r["height_diff_m"]) for r in planes])),
        "plane_height_diff_m_max_abs": max(abs(r["height_diff_m"]) for r in planes),
        "plane_fit_s_median": med(planes, "fit_s"),
        "depth_heldout_median_m": med(depth, "median_m"), "depth_heldout_p90_m_median": med(depth, "p90_m"),
        "depth_coverage_median": med(depth, "coverage"), "depth_densify_s_median": med(depth, "densify_s"),
        "depth_minfilter_median_m": med(depth, "minfilter_median_m"),
        "depth_minfilter_p90_m_median": med(depth, "minfilter_p90_m"),
        "depth_minfilter_coverage_median": med(depth, "minfilter_coverage"),
        "beams_scans": n, "beams_top_deg": round(float(el[0]), 3), "beams_bottom_deg": round(float(el[-1]), 3),
        "beams_upper_spacing_deg": round(float(-np.diff(el[:32]).mean()), 3),
        "beams_lower_spacing_deg": round(float(-np.diff(el[32:]).mean()), 3),
        "azimuth_step_deg": round(step, 4),
        "people_reflectance": people_reflectance(root, names),
        "per_frame": {"plane": planes, "depth": depth},
    }
    if bike and avatar:
        import torch

        torch.set_num_threads(2)
        cyc = demo_cyclist(bike, avatar)
        on = frames[min(1, len(frames) - 1)]
        rows = insert_timing(on, cyc, INSERT_SPOTS, repeats)
        out.update(insert_s_per_cyclist_median=float(np.median([r["seconds"] for r in rows])),
                   insert_points_median=float(np.median([r["points"] for r in rows])), insert=rows,
                   insert_frame=on["name"], insert_bike=bike, insert_avatar=avatar)
        if image:
            from bench.lidar_bev import draw_bev

            out["image"] = {"path": image, "frame": frames[image_frame]["name"],
                            **draw_bev(frames[image_frame], cyc, image)}
    else:
        out["insert"] = "skipped: no trained bike and rider avatar"
    return out


def have_cyclist(bike, avatar):
    return os.path.isfile(os.path.join(bike, "gaussians", "frame.ply")) and \
        os.path.isfile(os.path.join(avatar, "rider.ply"))


def run(results, out=None, root=DEV):
    """make bench's stage (bench/run.py): the summary numbers as lidar_* keys; nothing without the
    development frames; the insertion timing with the demo's bike and rider when built."""
    if not os.path.isdir(os.path.join(root, "velodyne")):
        print(f"bench lidar: no development frames at {root}, skipped")
        return
    bike, avatar = os.path.join(DEMO, "bikes", "city_00"), os.path.join(DEMO, "riders", "m_adult_average_185")
    ok = have_cyclist(bike, avatar)
    m = measure(root, bike if ok else None, avatar if ok else None)
    results.update({"lidar_" + k: v for k, v in m.items() if isinstance(v, (int, float))})
    results["lidar_people_reflectance"] = m["people_reflectance"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", default=DEV, help="a KITTI object folder with calib, velodyne, planes, image_2")
    ap.add_argument("--bike", help="a trained bike folder for the insertion timing (default: the demo's)")
    ap.add_argument("--avatar", help="a rider avatar folder (default: the demo's)")
    ap.add_argument("--repeats", type=int, default=3, help="insertion timings per cyclist (median)")
    ap.add_argument("--image", help="also draw the bird's-eye view picture (PNG) of frame --image-frame")
    ap.add_argument("--image-frame", type=int, default=1, help="index into the frames (default 1: 000001's open road)")
    a = ap.parse_args(argv)
    if not os.path.isdir(os.path.join(a.frames, "velodyne")):
        sys.exit(f"bench/lidar.py: {a.frames} has no velodyne/ folder")
    bike = a.bike or os.path.join(DEMO, "bikes", "city_00")
    avatar = a.avatar or os.path.join(DEMO, "riders", "m_adult_average_185")
    if (a.bike or a.avatar or a.image) and not have_cyclist(bike, avatar):
        sys.exit(f"bench/lidar.py: no trained bike in {bike} or rider avatar in {avatar}")
    if a.repeats < 1:
        sys.exit("bench/lidar.py: --repeats must be >= 1")
    if a.image and not os.access(os.path.dirname(os.path.abspath(a.image)), os.W_OK):
        sys.exit(f"bench/lidar.py: cannot write {a.image} (no such folder or not writable)")
    names = frame_names(a.frames)
    if not names or not 0 <= a.image_frame < len(names):
        sys.exit(f"bench/lidar.py: --image-frame {a.image_frame} is not one of the {len(names)} frames")
    ok = have_cyclist(bike, avatar)
    out = measure(a.frames, bike if ok else None, avatar if ok else None, a.repeats, a.image, a.image_frame)
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()

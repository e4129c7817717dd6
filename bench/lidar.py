"""LiDAR geometry on the KITTI development frames (docs/kitti_lidar.md); prints one JSON object.

- plane: the RANSAC road plane of every frame's scan against its planes/*.txt (angle between the
  normals, camera height difference, and the largest height difference of the two planes over
  the road 5-40 m ahead, |x| < 10 m), and the fit's time;
- depth: the densified LiDAR depth image's error on held-out points (10 % of each scan's points
  hidden, the image built from the rest, |depth - hidden point's depth| at the pixels that
  only hidden points fall in), with and without densification's coverage;
- beams: the HDL-64E table and azimuth step estimated from the scans (hdl64.estimate_beams);
- insert: insert_into_scan's time per cyclist on a development scan, with --bike / --avatar (a
  trained bike folder and rider avatar; default: the demo's in out/demo when present).

    .venv/bin/python bench/lidar.py [--frames ../shared/realism/kitti_dev] [--bike DIR --avatar DIR]
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
    return {"pixels": int(m.sum()), "coverage": float(got.mean()), "median_m": float(np.median(err)),
            "p90_m": float(np.percentile(err, 90)), "median_rel": float(np.median(err / hidden[m][got])),
            "densify_s": dt}


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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", default=DEV, help="a KITTI object folder with calib, velodyne, planes, image_2")
    ap.add_argument("--bike", help="a trained bike folder for the insertion timing (default: the demo's)")
    ap.add_argument("--avatar", help="a rider avatar folder (default: the demo's)")
    ap.add_argument("--repeats", type=int, default=3, help="insertion timings per cyclist (median)")
    a = ap.parse_args(argv)
    if not os.path.isdir(os.path.join(a.frames, "velodyne")):
        sys.exit(f"bench/lidar.py: {a.frames} has no velodyne/ folder")
    names = sorted(f[:-4] for f in os.listdir(os.path.join(a.frames, "velodyne")) if f.endswith(".bin"))
    frames = [read_frame(a.frames, int(n)) for n in names]
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
        "beams_scans": n, "beams_top_deg": round(float(el[0]), 3), "beams_bottom_deg": round(float(el[-1]), 3),
        "beams_upper_spacing_deg": round(float(-np.diff(el[:32]).mean()), 3),
        "beams_lower_spacing_deg": round(float(-np.diff(el[32:]).mean()), 3),
        "azimuth_step_deg": round(step, 4),
        "per_frame": {"plane": planes, "depth": depth},
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()

"""LiDAR geometry of real frames (splatting/dataset/frames/lidar.py, hdl64.py, scan_insert.py) on
synthetic scans whose scene is known exactly: a ground plane, walls and boxes ray-cast with the
HDL-64E beam model, and a box-shaped 'cyclist' made of surface Gaussians."""
import math
import os

import numpy as np
import pytest
import torch

from splatting.dataset.frames import hdl64, lidar
from splatting.dataset.frames.scan_insert import insert_into_scan
from splatting.gaussians.container import Gaussians

# KITTI-like axes: rect x = -velo y, rect y = -velo z, rect z = velo x; the sensor 8 cm above and
# 27 cm behind the camera, so the road (1.73 m below the sensor) is 1.65 m below the camera
T = np.array([[0, -1, 0, 0], [0, 0, -1, -0.08], [1, 0, 0, -0.27], [0, 0, 0, 1]], np.float64)
ORIGIN = T[:3, 3]
ROAD_Y = 1.65
P2 = np.array([[700.0, 0, 620, 0], [0, 700.0, 180, 0], [0, 0, 1, 0]])
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# the repository's sibling shared/ (main checkout) or the worktrees' grand-parent's one
DEV = next((p for p in (os.path.join(ROOT, "..", "shared", "realism", "kitti_dev"),
                        os.path.join(ROOT, "..", "..", "shared", "realism", "kitti_dev")) if os.path.isdir(p)), "")


def ray_box(o, d, lo, hi):
    """Entry distance of rays o + t d (d (N, 3)) into the axis-aligned box [lo, hi]; inf if missed."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - o) / d, (hi - o) / d
    tn = np.nanmax(np.minimum(t1, t2), 1)
    tf = np.nanmin(np.maximum(t1, t2), 1)
    return np.where((tf >= tn) & (tf > 0), np.maximum(tn, 0), np.inf)


def cast_scan(boxes=(), az_deg=(-40, 40), plane=(0.0, -1.0, 0.0, ROAD_Y), phase_deg=0.07, beams=hdl64.HDL64E):
    """A synthetic scan: every laser at every firing in the azimuth sector, first hit on the road
    plane (rect a x + b y + c z + d = 0) or on one of the rect boxes [(lo, hi)], reflectance 0.5."""
    lasers = beams.elevations_rad()
    step = beams.azimuth_step_deg
    az = np.radians(np.arange(az_deg[0], az_deg[1], step) + phase_deg)
    E, A = np.meshgrid(lasers, az, indexing="ij")
    dv = hdl64.directions(E.ravel(), A.ravel())
    dr = dv @ T[:3, :3].T
    pl = np.asarray(plane, np.float64)
    with np.errstate(divide="ignore"):
        t = -(ORIGIN @ pl[:3] + pl[3]) / (dr @ pl[:3])
    t = np.where(t > 0, t, np.inf)
    for lo, hi in boxes:
        t = np.minimum(t, ray_box(ORIGIN, dr, np.asarray(lo, float), np.asarray(hi, float)))
    ok = t < 80
    pts = dv[ok] * t[ok, None]
    return np.concatenate([pts, np.full((len(pts), 1), 0.5)], 1).astype(np.float32)


def box_gaussians(lo, hi, spacing=0.02, sigma=0.012, thin=0.002):
    """Flat Gaussians tiling the surface of the rect box [lo, hi] (opacity 0.99)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    means, scales = [], []
    for ax in range(3):
        u, v = [a for a in range(3) if a != ax]
        gu = np.arange(lo[u] + spacing / 2, hi[u], spacing)
        gv = np.arange(lo[v] + spacing / 2, hi[v], spacing)
        U, V = np.meshgrid(gu, gv, indexing="ij")
        for side in (lo[ax], hi[ax]):
            m = np.zeros((U.size, 3))
            m[:, u], m[:, v], m[:, ax] = U.ravel(), V.ravel(), side
            s = np.full((U.size, 3), sigma)
            s[:, ax] = thin
            means.append(m)
            scales.append(s)
    m, s = np.concatenate(means), np.concatenate(scales)
    n = len(m)
    q = np.zeros((n, 4))
    q[:, 0] = 1
    return Gaussians(torch.tensor(m, dtype=torch.float32), torch.tensor(q, dtype=torch.float32),
                     torch.tensor(np.log(s), dtype=torch.float32), torch.full((n,), math.log(0.99 / 0.01)),
                     torch.zeros(n, 1, 3))


def box_distance(p, lo, hi):
    """Distance of rect points to the surface of the box [lo, hi]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c, h = (lo + hi) / 2, (hi - lo) / 2
    q = np.abs(p - c) - h
    outside = np.linalg.norm(np.maximum(q, 0), axis=1)
    inside = np.minimum(q.max(1), 0)
    return np.abs(outside + inside)


# the 'cyclist': 0.6 m wide, 1.7 m tall, 1.6 m long, standing on the road 12 m ahead
CYC = ((-0.3, ROAD_Y - 1.7, 11.2), (0.3, ROAD_Y, 12.8))


def grow(box, m):
    return tuple(np.array(box[0]) - m), tuple(np.array(box[1]) + m)


def ray_hits(points_velo, box):
    """(N,) bool: the ray from the sensor to each velo point enters the rect box before it."""
    p = np.asarray(points_velo, np.float64)[:, :3]
    r = np.linalg.norm(p, axis=1)
    d = (p / r[:, None]) @ T[:3, :3].T
    return ray_box(ORIGIN, d, np.asarray(box[0], float), np.asarray(box[1], float)) < r


# --- beam model -------------------------------------------------------------------------------

def test_beam_model_sanity():
    for b in (hdl64.HDL64E, hdl64.HDL64E_NOMINAL):
        el = np.asarray(b.elevations_deg)
        assert len(el) == 64 and (np.diff(el) < 0).all()
        assert 1.5 < el[0] < 3.0 and -25.5 < el[-1] < -23.0
        assert 0.25 < -np.diff(el[:32]).mean() < 0.4  # upper block ~1/3 deg
        assert 0.4 < -np.diff(el[32:]).mean() < 0.6   # lower block ~1/2 deg
    assert hdl64.HDL64E.n_azimuth == 2000
    b = hdl64.HDL64E
    el = b.elevations_rad()
    assert (b.beam_index(el) == np.arange(64)).all()
    assert (b.beam_index(el + 0.4 * np.r_[np.diff(el), -1e-3]) == np.arange(64)).all()
    assert (b.azimuth_bin(b.azimuth_of_bin(np.arange(0, 2000, 7))) == np.arange(0, 2000, 7)).all()


def test_estimate_beams_recovers_a_known_table():
    # a scan in KITTI's file order: laser by laser, each sweep starting straight ahead
    rng = np.random.default_rng(3)
    truth = hdl64.HDL64E_NOMINAL
    rows = []
    for e in truth.elevations_rad():
        az = np.radians(np.arange(0.05, 360, truth.azimuth_step_deg))
        az = az[rng.random(len(az)) > 0.1]  # missing returns
        r = rng.uniform(6, 40, len(az))
        rows.append(hdl64.directions(np.full(len(az), e), az) * r[:, None])
    el, step, n = hdl64.estimate_beams([np.concatenate(rows)])
    assert n == 1
    assert np.abs(el - np.asarray(truth.elevations_deg)).max() < 1e-6
    assert abs(step - truth.azimuth_step_deg) < 1e-3
    with pytest.raises(ValueError, match="64 rings"):
        hdl64.estimate_beams([np.concatenate(rows[:10])])


@pytest.mark.skipif(not os.path.isdir(os.path.join(DEV, "velodyne")), reason="no development frames")
def test_kitti_table_is_the_dev_scans_estimate():
    scans = [np.fromfile(os.path.join(DEV, "velodyne", f), np.float32).reshape(-1, 4)
             for f in sorted(os.listdir(os.path.join(DEV, "velodyne")))]
    el, step, n = hdl64.estimate_beams(scans)
    assert n == 10
    assert np.abs(el - np.asarray(hdl64.KITTI_ELEVATIONS_DEG)).max() < 1e-3
    assert abs(step - hdl64.KITTI_AZIMUTH_STEP_DEG) < 1e-3


# --- ground plane -----------------------------------------------------------------------------

def tilted_plane(deg, height):
    n = np.array([0.0, -math.cos(math.radians(deg)), math.sin(math.radians(deg))])
    return np.r_[n, height]


def test_fit_ground_plane_known_answer_with_clutter():
    truth = tilted_plane(2.0, 1.6)
    boxes = [((-3, -0.5, 8), (-1, 1.6, 12)), ((1.5, -2, 15), (2.5, 2, 16)), ((-8, -3, 5), (-6, 2, 30))]
    s = cast_scan(boxes, az_deg=(-60, 60), plane=truth)
    rng = np.random.default_rng(0)
    s[:, :3] += rng.normal(0, 0.02, (len(s), 3)).astype(np.float32)  # range noise
    clutter = rng.uniform([2, -15, -2], [40, 15, 1], (len(s) // 5, 3))  # floating points above the road
    s = np.concatenate([s, np.c_[clutter, np.zeros(len(clutter))].astype(np.float32)])
    p = lidar.fit_ground_plane(s, T, 0)
    ang = math.degrees(math.acos(min(1.0, p[:3] @ truth[:3])))
    assert ang < 0.2 and abs(p[3] - truth[3]) < 0.02, (p, truth)
    assert p[1] < 0  # the planes-file sign: normal up
    # the fitted heights of the true road's points are ~0
    road = lidar.velo_to_rect(cast_scan((), plane=truth)[:, :3], T)
    assert np.abs(lidar.plane_height(road, p)).max() < 0.05


def test_fit_ground_plane_refuses_implausible_scenes():
    with pytest.raises(ValueError, match="no road plane|no plausible"):
        lidar.fit_ground_plane(cast_scan(plane=tilted_plane(25.0, 1.6)), T, 0)  # a steep slope
    with pytest.raises(ValueError, match="no road plane|no plausible"):
        lidar.fit_ground_plane(cast_scan(plane=(0, -1, 0, 3.5)), T, 0)  # road 3.5 m below the camera
    with pytest.raises(ValueError, match="points below the sensor"):
        lidar.fit_ground_plane(np.zeros((10, 4), np.float32), T, 0)


@pytest.mark.skipif(not os.path.isdir(os.path.join(DEV, "planes")), reason="no development frames")
def test_fit_ground_plane_agrees_with_dev_planes():
    from bench.lidar import read_frame

    for i in range(10):
        f = read_frame(DEV, i)
        p = lidar.fit_ground_plane(f["scan"], f["T"], 0)
        q = lidar.normalise_plane(f["plane"])
        assert math.degrees(math.acos(min(1.0, p[:3] @ q[:3]))) < 2.5
        assert abs(p[3] - q[3]) < 0.15


# --- support, shadows, boxes ------------------------------------------------------------------

WALL = ((-2.0, ROAD_Y - 2.5, 20.0), (2.0, ROAD_Y, 20.3))  # a wall 20 m ahead, 2.5 m tall


def square(cx, cz, half=0.4):
    return np.array([[cx - half, cz - half], [cx + half, cz - half], [cx + half, cz + half], [cx - half, cz + half]])


def test_ground_support_and_shadow():
    s = cast_scan([WALL])
    plane = (0, -1, 0, ROAD_Y)
    open_road = lidar.ground_support(s, T, plane, square(0, 12))
    assert open_road["ground"] > 20 and open_road["obstacle"] == 0
    on_wall = lidar.ground_support(s, T, plane, square(0, 20.15))
    assert on_wall["obstacle"] > 20
    behind = lidar.ground_support(s, T, plane, square(0, 24))
    assert behind["ground"] == 0  # the wall's shadow: no road seen there
    beside = lidar.ground_support(s, T, plane, square(4.0, 24))
    assert beside["ground"] > 5
    spots = np.array([[0, ROAD_Y, 12], [0, ROAD_Y, 24], [0, ROAD_Y - 1.0, 24], [4.0, ROAD_Y, 24]])
    vis = lidar.visible_ground(s, T, plane, spots)
    assert vis.tolist() == [True, False, False, True]
    assert (lidar.shadow_blockers(s, T, plane, spots)[[1, 2]] > 3).all()


def test_points_in_box_known_answer():
    rng = np.random.default_rng(1)
    box = (1.7, 0.6, 1.8, 2.0, 1.6, 15.0, 0.7)  # h w l x y z ry
    local = rng.uniform(-1, 1, (4000, 3)) * [1.2, 1.2, 1.2]  # object axes, units of half sizes
    inside = (np.abs(local) < 1).all(1)
    lx, ly, lz = local[:, 0] * 0.9, (local[:, 1] - 1) * 0.85, local[:, 2] * 0.3
    c, s = math.cos(0.7), math.sin(0.7)
    rect = np.stack([c * lx + s * lz + 2.0, ly + 1.6, -s * lx + c * lz + 15.0], 1)  # R_y(ry) local + loc
    assert (lidar.in_box(rect, box) == inside).all()
    velo = lidar.rect_to_velo(rect, T)
    assert lidar.points_in_box(velo, T, box) == int(inside.sum())
    # KITTI's convention: at ry = pi / 2 the length runs along rect -z
    assert lidar.in_box(np.array([[0, -0.5, -0.8], [0.8, -0.5, 0]]), (1, 0.4, 2, 0, 0, 0, math.pi / 2)).tolist() \
        == [True, False]


# --- depth image ------------------------------------------------------------------------------

def test_depth_image_known_answer():
    near = ((-1.0, ROAD_Y - 1.5, 8.0), (1.0, ROAD_Y, 9.0))  # a box 8 m ahead, before a far wall
    far = ((-15.0, ROAD_Y - 6, 25.0), (15.0, ROAD_Y, 25.5))
    s = cast_scan([near, far])
    W, H = 1240, 370
    D = lidar.lidar_depth_image(s, T, P2, W, H)
    assert D.shape == (H, W) and D.dtype == np.float32
    uv = lambda x, y, z: (P2[:, :3] @ [x, y, z] + P2[:, 3])[:2] / z  # noqa: E731
    # interior of the near box's face: every pixel filled, at 8 m
    (u0, v0), (u1, v1) = uv(-0.9, ROAD_Y - 1.4, 8.0), uv(0.9, ROAD_Y - 0.1, 8.0)
    face = D[int(v0):int(v1), int(u0):int(u1)]
    assert (face > 0).all() and np.abs(face - 8.0).max() < 0.02
    # the far wall beside it: 25 m, and not fattened by the near box more than a few pixels
    (w0, _), (w1, vb) = uv(1.0, 0, 8.0), uv(4.0, ROAD_Y - 0.3, 25.0)  # rows above the wall's foot
    wall = D[int(v0):int(vb), int(w0) + 4:int(w1)]
    assert (wall > 0).all() and np.abs(wall - 25.0).max() < 0.05
    # above the wall's top and the top laser: unknown
    _, vt = uv(0, ROAD_Y - 6 - 0.5, 25.0)
    top = min(vt, uv(0, -25 * math.tan(math.radians(hdl64.HDL64E.elevations_deg[0])) - 0.08, 25.0)[1])
    assert (D[:max(int(top) - 8, 1)] == 0).all()


@pytest.mark.skipif(not os.path.isdir(os.path.join(DEV, "velodyne")), reason="no development frames")
def test_depth_image_held_out_points_dev():
    from bench.lidar import held_out_depth_error, read_frame

    errs = [held_out_depth_error(read_frame(DEV, i), seed=i)["median_m"] for i in (0, 5)]
    assert max(errs) < 0.1


# --- insertion --------------------------------------------------------------------------------

def test_insert_hits_on_the_surface_and_shadows_exactly():
    s = cast_scan([WALL])
    g = box_gaussians(*CYC)
    new, counts, removed = insert_into_scan(s, T, [g], range_noise_m=0.0, rng=0)
    added = new[int((~removed).sum()):]
    assert counts == [len(added)] and len(added) > 300
    rect = lidar.velo_to_rect(added[:, :3], T)
    d = box_distance(rect, *CYC)
    assert d.max() < 0.03 and np.median(d) < 0.01, (d.max(), np.median(d))
    assert ((added[:, 3] >= 0.14) & (added[:, 3] <= 0.53)).all() and added[:, 3].std() > 0.05
    # hits on every face the sensor sees: front (z = 11.2), left side (x = -0.3: the sensor is at
    # x = 0, so it sees neither side) ... and the top is above the sensor? no: below, it sees the top
    assert (np.abs(rect[:, 2] - 11.2) < 0.03).sum() > 100
    assert (np.abs(rect[:, 1] - (ROAD_Y - 1.7)) < 0.03).sum() > 10
    # removed exactly where the silhouette covers: behind -> removed, beside -> kept
    inner, outer = ray_hits(s, grow(CYC, -0.02)), ray_hits(s, grow(CYC, 0.02))
    assert inner.sum() > 200
    assert removed[inner].all() and not removed[~outer].any()
    beside = (~outer) & (np.abs(lidar.velo_to_rect(s[:, :3], T)[:, 0]) < 1.0)
    assert beside.sum() > 50
    # the real points kept are the input's, bit for bit, in order
    assert np.array_equal(new[:int((~removed).sum())], s[~removed])


def test_insert_range_noise_is_seeded():
    s = cast_scan([])
    g = box_gaussians(*CYC)
    a, ca, _ = insert_into_scan(s, T, [g], rng=5)
    b, cb, _ = insert_into_scan(s, T, [g], rng=5)
    assert np.array_equal(a, b) and ca == cb
    added = a[len(a) - ca[0]:]
    res = box_distance(lidar.velo_to_rect(added[:, :3], T), *CYC)
    assert 0.008 < np.median(res) < 0.02  # 1.5 cm normal noise: median |noise| ~ 1 cm


def test_lasers_fire_at_their_own_azimuth_phases():
    s = cast_scan([])
    g = box_gaussians(*CYC)
    step = hdl64.HDL64E.azimuth_step_deg

    def phases(**kw):
        new, counts, _ = insert_into_scan(s, T, [g], range_noise_m=0.0, rng=1, **kw)
        a = new[len(new) - counts[0]:]
        laser = hdl64.HDL64E.beam_index(np.arctan2(a[:, 2], np.hypot(a[:, 0], a[:, 1])))
        ph = np.degrees(np.arctan2(a[:, 1], a[:, 0])) % step
        return {int(L_): ph[laser == L_] for L_ in np.unique(laser)}

    one = phases(phase_deg=0.0)
    assert len(one) > 10 and all(np.minimum(p, step - p).max() < 1e-3 for p in one.values())
    own = phases()
    wrap = lambda d: (d + step / 2) % step - step / 2  # noqa: E731
    assert len(own) > 10 and all(np.abs(wrap(p - p[0])).max() < 1e-3 for p in own.values())  # one per laser
    assert np.std([p[0] for p in own.values()]) > step / 6  # ... and they differ


def test_wall_in_front_hides_the_cyclist():
    wall = ((-2.0, ROAD_Y - 2.5, 7.0), (2.0, ROAD_Y, 7.2))
    s = cast_scan([wall])
    new, counts, removed = insert_into_scan(s, T, [box_gaussians(*CYC)], rng=0)
    assert counts == [0]
    assert not removed.any() and np.array_equal(new, s)


def test_half_wall_hides_half():
    wall = ((-2.0, ROAD_Y - 2.5, 7.0), (0.0, ROAD_Y, 7.2))  # covers the cyclist's rect x < 0 half
    s = cast_scan([wall])
    new, counts, removed = insert_into_scan(s, T, [box_gaussians(*CYC)], range_noise_m=0.0, rng=0)
    added = new[len(new) - counts[0]:]
    assert counts[0] > 100
    # no added point whose ray crosses the wall (beyond one azimuth cell of its edge)
    assert not ray_hits(added, grow(wall, -0.03)).any()
    on_wall = np.abs(lidar.velo_to_rect(s[:, :3], T)[:, 2] - 7.0) < 0.01
    assert on_wall.sum() > 100 and not removed[on_wall].any()
    # removed exactly where the unhidden part of the silhouette covers: the wall's points, in
    # front, stay; the road behind the cyclist's right half goes
    inner, outer = ray_hits(s, grow(CYC, -0.02)), ray_hits(s, grow(CYC, 0.02))
    assert removed.sum() > 50 and inner.sum() > 50
    assert removed[inner].all() and not removed[~outer].any()


def test_two_cyclists_occlude_each_other():
    front = ((-0.3, ROAD_Y - 1.7, 8.0), (0.3, ROAD_Y, 9.6))
    s = cast_scan([])
    new, counts, removed = insert_into_scan(s, T, [box_gaussians(*CYC), box_gaussians(*front)], rng=0)
    # the nearer one, inserted second, removes the farther one's points behind it: only the
    # farther one's top (seen over the nearer's, which stands lower in the view) survives
    added = new[len(new) - sum(counts):]
    far_pts = lidar.velo_to_rect(added[:counts[0], :3], T)
    assert counts[1] > 100
    assert not ray_hits(added[:counts[0]], grow(front, -0.02)).any()
    assert len(far_pts) == 0 or (box_distance(far_pts, *CYC) < 0.06).all()


def test_bad_input_is_one_clear_error():
    g = box_gaussians(*CYC)
    with pytest.raises(ValueError, match=r"\(N, 4\)"):
        insert_into_scan(np.zeros((5, 3), np.float32), T, [g])
    with pytest.raises(ValueError, match="finite"):
        insert_into_scan(np.full((5, 4), np.nan, np.float32), T, [g])
    with pytest.raises(ValueError, match="eps2d has 2 entries"):
        insert_into_scan(np.zeros((5, 4), np.float32), T, [g], eps2d=[0.3, 0.3])
    with pytest.raises(ValueError, match="4 finite numbers"):
        lidar.plane_height(np.zeros((1, 3)), (0, -1, 0))
    with pytest.raises(ValueError, match="footprint"):
        lidar.ground_support(np.zeros((5, 4)), T, (0, -1, 0, 1.65), [[0, 1], [1, 1]])


@pytest.fixture(scope="module")
def stand_in():
    """A composed cyclist: stand-in bike and mesh rider, as the dataset tests use."""
    import tempfile

    from helpers import RIDER, write_test_bike
    from splatting.cyclist.assets import load_avatar, load_bike
    from splatting.cyclist.compose import Cyclist

    with tempfile.TemporaryDirectory() as root:
        return Cyclist(load_bike(write_test_bike(root), n_per_part=1500),
                       load_avatar(RIDER, root + "/none", n=4000)[0], ik_iterations=20)


def gaussian_gap(points_rect, g):
    """Distance of each point to the nearest Gaussian's 2-sigma ball (0 inside one)."""
    m, sig = g.means.double().numpy(), g.scales.double().numpy().max(1)
    return np.min(np.linalg.norm(points_rect[:, None] - m[None], axis=-1) - 2 * sig[None], axis=1)


def test_stand_in_cyclist_on_a_tilted_road(stand_in):
    """The cyclist stood on a 3 deg slope with canonical_to_rect: tyres on the road, heading as
    KITTI's rotation_y, its scan points on its Gaussians and inside its 3D box."""
    from splatting.bike.pose import transform_gaussians

    cyc = stand_in
    fr = cyc.pose(torch.tensor([30.0, 0, 0, 0, 0, 0, 0, 0], dtype=torch.float64))[0]
    plane, ry = tilted_plane(3.0, 1.65), 0.4
    H = lidar.canonical_to_rect(plane, 1.0, 11.0, ry)
    kp = {k: H[:3, :3] @ np.asarray(v, float) + H[:3, 3] for k, v in fr.bike_keypoints.items()}
    r_wheel = 0.693 / 2
    for axle in ("front_axle", "rear_axle"):  # both tyres touch the slope
        assert abs(lidar.plane_height(kp[axle][None], plane)[0] - r_wheel) < 0.01
    fwd = kp["front_axle"] - kp["rear_axle"]
    fwd_level = np.array([fwd[0], fwd[2]]) / np.hypot(fwd[0], fwd[2])
    assert np.allclose(fwd_level, [math.cos(ry), -math.sin(ry)], atol=1e-6)
    g = transform_gaussians(fr.gaussians, torch.as_tensor(H))
    s = cast_scan(plane=plane)
    new, counts, removed = insert_into_scan(s, T, [g], range_noise_m=0.0, rng=0)
    added = lidar.velo_to_rect(new[len(new) - counts[0]:, :3], T)
    assert counts[0] > 80 and removed.sum() > 30
    # every hit within 3 cm of some Gaussian's 2-sigma ball
    gap = gaussian_gap(added, g)
    assert gap.max() < 0.03, gap.max()
    m = g.means.double().numpy()
    # and inside the cyclist's 3D box (KITTI convention, from its Gaussians' extent + 5 cm)
    c, sn = math.cos(ry), math.sin(ry)
    Ry = np.array([[c, 0, sn], [0, 1, 0], [-sn, 0, c]])  # KITTI's: object axes -> rect, about y only
    local = m @ Ry
    lo, hi = local.min(0) - 0.05, local.max(0) + 0.05
    loc = Ry @ np.array([(lo[0] + hi[0]) / 2, hi[1], (lo[2] + hi[2]) / 2])
    box = (hi[1] - lo[1], hi[2] - lo[2], hi[0] - lo[0], loc[0], loc[1], loc[2], ry)
    assert 1.5 < box[2] < 2.2 and box[1] < 1.0  # the length runs along the heading
    inside = lidar.in_box(added, box)
    assert inside.mean() > 0.95
    assert lidar.points_in_box(new, T, box) >= inside.sum()


@pytest.mark.skipif(not os.path.isdir(os.path.join(DEV, "velodyne")), reason="no development frames")
def test_insert_into_a_dev_scan(stand_in):
    """A real scan and calibration: the cyclist on the fitted road 9 m ahead gets points on its
    Gaussians, shadows only real points behind it, and leaves the rest bit for bit."""
    from bench.lidar import read_frame
    from splatting.bike.pose import transform_gaussians

    f = read_frame(DEV, 1)
    plane = lidar.fit_ground_plane(f["scan"], f["T"], 0)
    fr = stand_in.pose(torch.tensor([30.0, 0, 0, 0, 0, 0, 0, 0], dtype=torch.float64))[0]
    g = transform_gaussians(fr.gaussians, torch.as_tensor(lidar.canonical_to_rect(plane, 1.8, 9.0, -math.pi / 2)))
    new, counts, removed = insert_into_scan(f["scan"], f["T"], [g], rng=0)
    assert counts[0] > 80 and removed.sum() > 20
    added = new[len(new) - counts[0]:]
    assert gaussian_gap(lidar.velo_to_rect(added[:, :3], f["T"]), g).max() < 0.05  # 1.5 cm noise on
    assert np.array_equal(new[:len(new) - counts[0]], f["scan"][~removed])
    # the shadowed points lie behind the cyclist, in its direction
    rr = np.linalg.norm(f["scan"][removed, :3], axis=1)
    assert rr.min() > np.linalg.norm(added[:, :3], axis=1).min()
    az = np.degrees(np.arctan2(f["scan"][removed, 1], f["scan"][removed, 0]))
    az_c = np.degrees(np.arctan2(added[:, 1], added[:, 0]))
    assert az.min() > az_c.min() - 1 and az.max() < az_c.max() + 1


@pytest.mark.skipif(not os.path.isdir(os.path.join(DEV, "velodyne")), reason="no development frames")
def test_dev_frame_parked_car_shadow_and_obstacle():
    """000008: the road behind a labelled parked car (seen from the sensor) is in its shadow, the
    open road ahead is seen; the car's footprint holds an obstacle, the road's does not."""
    from bench.lidar import read_frame

    f = read_frame(DEV, 8)
    plane = lidar.fit_ground_plane(f["scan"], f["T"], 0)
    o = lidar.sensor_origin_rect(f["T"])
    car = np.array([-1.17, 1.65 - 1.57 / 2, 7.86])  # the label's box centre (bottom y 1.65, h 1.57)

    def road(x, z):
        return [x, -(plane[0] * x + plane[2] * z + plane[3]) / plane[1], z]

    behind = [road(*(o + k * (car - o))[[0, 2]]) for k in (1.2, 1.5, 2.0)]
    vis = lidar.visible_ground(f["scan"], f["T"], plane, behind + [road(0.3, 11.0)])
    assert vis.tolist() == [False, False, False, True]
    foot = lambda x, z: [[x - 0.4, z - 0.9], [x + 0.4, z - 0.9], [x + 0.4, z + 0.9], [x - 0.4, z + 0.9]]  # noqa: E731
    assert lidar.ground_support(f["scan"], f["T"], plane, foot(-1.17, 7.86))["obstacle"] > 50
    s = lidar.ground_support(f["scan"], f["T"], plane, foot(0.3, 11.0))
    assert s["obstacle"] == 0 and s["ground"] > 50

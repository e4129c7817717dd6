"""Shared test factories: synthetic bikes, Gaussians, a city bike's keypoints, and a pure-Python
reference of the bike pose maths (independent of splatting.bike.pose, so tests can fail).

Tests import these (`from helpers import ...`) instead of importing each other.
"""
import json
import math
import os

import torch

from splatting.gaussians.container import Gaussians, write_ply
from splatting.gaussians.sh import rgb_to_sh0
from splatting.raster.camera import Camera

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPTS = os.path.join(ROOT, "blender_scripts")

KP = {  # a plausible 1 m-wheelbase bike, canonical frame (X forward, Y up, Z right)
    "seat": [-0.15, 0.95, 0.0], "steer_top": [0.38, 0.95, 0.0], "steer_bottom": [0.45, 0.70, 0.0],
    "handle_left": [0.33, 1.0, -0.25], "handle_right": [0.33, 1.0, 0.25], "crank_axle": [0.0, 0.30, 0.0],
    "pedal_left": [-0.17, 0.30, -0.12], "pedal_right": [0.17, 0.30, 0.12], "front_axle": [0.60, 0.35, 0.0],
    "rear_axle": [-0.50, 0.35, 0.0], "ground": [0.0, 0.0, 0.0],
}
KP_PARTS = {"frame": ["seat", "steer_top", "steer_bottom", "rear_axle", "ground", "crank_axle"],
            "steering": ["handle_left", "handle_right", "front_axle"], "crank": ["pedal_left", "pedal_right"]}
# the keypoints each part's Gaussians cluster around; the first Gaussian sits exactly on the first
ANCHORS = {"frame": ["seat", "rear_axle"], "steering": ["front_axle", "handle_left"],
           "crank": ["pedal_right", "pedal_left"], "front_wheel": ["front_axle"], "rear_wheel": ["rear_axle"],
           "pedal_left": ["pedal_left"], "pedal_right": ["pedal_right"]}


def random_gaussians(n, centre_names, sh_degree=3, seed=0):
    g = torch.Generator().manual_seed(seed)
    centres = torch.tensor([KP[c] for c in centre_names])
    means = centres[torch.randint(len(centres), (n,), generator=g)] + 0.08 * torch.randn(n, 3, generator=g)
    means[0] = centres[0]
    k = (sh_degree + 1) ** 2
    return Gaussians(means=means, quats=torch.randn(n, 4, generator=g), log_scales=torch.randn(n, 3, generator=g) - 4,
                     opacity_logits=torch.randn(n, generator=g), sh=torch.randn(n, k, 3, generator=g) * 0.3)


def make_bike(root, bike_id="synth_01", crank=True, n=200, sh_degree=3, kp=None, sub_parts=(), meta_extra=None):
    """Write a synthetic bike folder (docs/contract.md layout) and return its path."""
    d = os.path.join(str(root), bike_id)
    os.makedirs(os.path.join(d, "gaussians"), exist_ok=True)
    parts = ["frame", "steering"] + (["crank"] if crank else []) + list(sub_parts)
    for i, p in enumerate(parts):
        write_ply(random_gaussians(n + 17 * i, ANCHORS[p], sh_degree, seed=i), os.path.join(d, "gaussians", p + ".ply"))
    kps = dict(kp or KP)
    kp_parts = {p: list(v) for p, v in KP_PARTS.items()}
    if not crank:
        for k in ("crank_axle", "pedal_left", "pedal_right"):
            kps.pop(k, None)
        kp_parts["frame"].remove("crank_axle")
        kp_parts.pop("crank")
    with open(os.path.join(d, "keypoints.json"), "w") as f:
        json.dump({"frame": "canonical", "units": "m", "keypoints": kps, "parts": kp_parts}, f)
    meta = {"bike_id": bike_id, "has_crank": crank}
    meta.update(meta_extra or {})
    with open(os.path.join(d, "meta.json"), "w") as f:
        json.dump(meta, f)
    return d


# ------------------------------------------------------------- reference math (pure Python)

def mat_vec(M, v):
    return [sum(M[i][j] * v[j] for j in range(3)) for i in range(3)]


def mat_mul(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def rodrigues(axis, angle):
    n = math.sqrt(sum(a * a for a in axis))
    x, y, z = (a / n for a in axis)
    c, s, C = math.cos(angle), math.sin(angle), 1 - math.cos(angle)
    return [[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C]]


def rotate_about(p, centre, axis, angle):
    r = mat_vec(rodrigues(axis, angle), [a - b for a, b in zip(p, centre)])
    return [a + b for a, b in zip(r, centre)]


def ref_global(p, pose):
    """x, then y, then z rotation about the world axes, then translate."""
    ax, ay, az = (math.radians(a) for a in pose[2:5])
    for axis, ang in (([1, 0, 0], ax), ([0, 1, 0], ay), ([0, 0, 1], az)):
        p = mat_vec(rodrigues(axis, ang), p)
    return [a + t for a, t in zip(p, pose[5:8])]


def ref_global_R(pose):
    ax, ay, az = (math.radians(a) for a in pose[2:5])
    return mat_mul(rodrigues([0, 0, 1], az), mat_mul(rodrigues([0, 1, 0], ay), rodrigues([1, 0, 0], ax)))


def steer_axis():
    return [a - b for a, b in zip(KP["steer_top"], KP["steer_bottom"])]


def ref_part_R(part, pose):
    R = ref_global_R(pose)
    if part == "steering":
        return mat_mul(R, rodrigues(steer_axis(), math.radians(pose[1])))
    if part == "crank":
        return mat_mul(R, rodrigues([0, 0, 1], -math.radians(pose[0])))
    return R


def ref_part_point(part, p, pose):
    if part == "steering":
        p = rotate_about(p, KP["steer_bottom"], steer_axis(), math.radians(pose[1]))
    elif part == "crank":
        p = rotate_about(p, KP["crank_axle"], [0, 0, 1], -math.radians(pose[0]))
    return ref_global(p, pose)


def quat_to_R(q):
    w, x, y, z = (float(a) for a in q)
    n = w * w + x * x + y * y + z * z
    w, x, y, z = (a / math.sqrt(n) for a in (w, x, y, z))
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]


def random_pose(rng):
    return [rng.uniform(-180, 180), rng.uniform(-60, 60), rng.uniform(-15, 15), rng.uniform(-180, 180),
            rng.uniform(-15, 15), rng.uniform(-3, 3), rng.uniform(-1, 1), rng.uniform(-3, 3)]


RIDER = "m_adult_average_185"

# a city bike's keypoints (canonical frame, metres), as the procedural generator writes them
CITY_KEYPOINTS = {
    "seat": [-0.2253, 0.9537, 0.0], "pedal_left": [-0.1737, 0.2764, -0.134], "pedal_right": [0.1737, 0.2764, 0.134],
    "steer_top": [0.3888, 0.8964, 0.0], "steer_bottom": [0.4591, 0.7200, 0.0],
    "handle_right": [0.2314, 1.0829, 0.2990], "handle_left": [0.2314, 1.0829, -0.2990],
    "crank_axle": [0.0, 0.2764, 0.0], "front_axle": [0.6662, 0.3466, 0.0], "rear_axle": [-0.4584, 0.3466, 0.0],
    "ground": [-0.4584, 0.0, 0.0]}


def write_test_bike(root, bike_id="city_t"):
    """A bike folder with keypoints and meta but no trained Gaussians (the pipeline builds stand-ins)."""
    d = os.path.join(root, bike_id)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "keypoints.json"), "w") as f:
        json.dump({"frame": "canonical", "units": "m", "keypoints": CITY_KEYPOINTS,
                   "parts": {"steering": ["steer_top", "steer_bottom", "handle_left", "handle_right", "front_axle"],
                             "crank": ["crank_axle", "pedal_left", "pedal_right"]}}, f)
    with open(os.path.join(d, "meta.json"), "w") as f:
        json.dump({"bike_id": bike_id, "has_crank": True, "dimensions": {"wheel_diameter_m": 0.693},
                   "spec": {"frame_colour": [0.05, 0.1, 0.4]}}, f)
    return d


def small_config(bikes_root, **kw):
    cfg = {"name": "t", "mode": "cyclist", "seed": 3, "count": 6, "image_size": 64, "riders": [RIDER],
           "bikes": ["city_t"], "bikes_root": bikes_root, "riders_root": os.path.join(bikes_root, "no_avatars"),
           "synthetic_gaussians_per_part": 600, "rider_gaussians": 2500, "ik_iterations": 10,
           "png_compress_level": 1, "synthetic_assets": "always"}  # stand-ins are an explicit opt-in (issue 15)
    cfg.update(kw)
    return cfg


def write_yaml(path, cfg):
    import yaml
    with open(path, "w") as f:
        yaml.safe_dump(cfg, f)
    return path


def dataset_main(cfg, tmp_path):
    """(exit code, stderr stripped) of `dataset --config <cfg as yaml> --out tmp_path/o --quiet`, in process."""
    import contextlib
    import io

    from splatting.cli import main
    path = write_yaml(str(tmp_path / "c.yaml"), cfg)
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(["dataset", "--config", path, "--out", str(tmp_path / "o"), "--quiet"])
    return rc, err.getvalue().strip()


# ------------------------------------------------------------- street scenes

def street_config(root, **kw):
    cfg = small_config(root, mode="street", count=2, camera={"preset": "kitti", "scale": 0.5},
                       street={"cyclists": [2, 3], "parked_bikes": [0, 1], "distance_m": [5, 15]})
    cfg.pop("image_size")
    for k, v in kw.items():
        cfg[k] = dict(cfg.get(k, {}), **v) if isinstance(v, dict) and isinstance(cfg.get(k), dict) else v
    return cfg


def fixed_scene(monkeypatch, instances, kind="solid"):
    """Make every sample the given instances [(rider or None, theta_y, x, z)]: the scene under test."""
    from splatting.dataset import generate
    inst = [{"kind": "cyclist" if r else "parked", "bike": "city_t", "rider": r,
             "pose": [30.0, 0.0, 0.0, yaw, 0.0, x, 0.0, z]} for r, yaw, x, z in instances]
    monkeypatch.setattr(generate, "draw", lambda cfg, index: {
        "instances": inst, "dropped": 0, "camera": {"preset": cfg.camera.preset},
        "background": {"kind": kind, "seed": 1}})


# ------------------------------------------------------------- rasterizer scenes and cameras

def look_at_camera(eye, target=(0.0, 0.0, 0.0), width=24, height=20, focal=28.0, cx=None, cy=None,
                   dtype=torch.float64):
    """OpenCV camera at `eye` looking at `target`, world +Y roughly image-up."""
    eye, target = torch.tensor(eye, dtype=dtype), torch.tensor(target, dtype=dtype)
    z = target - eye
    z = z / z.norm()
    x = torch.linalg.cross(z, torch.tensor([0.0, 1.0, 0.0], dtype=dtype))  # image-right
    x = x / x.norm()
    y = torch.linalg.cross(z, x)  # image-down
    R = torch.stack([x, y, z])
    T = -R @ eye
    K = torch.tensor([[focal, 0.0, width / 2 if cx is None else cx],
                      [0.0, focal * 1.1, height / 2 if cy is None else cy], [0.0, 0.0, 1.0]], dtype=dtype)
    return Camera(R, T, K, width, height)


def random_scene(gen, n, sh_degree, dtype=torch.float64, spread=1.0):
    means = (torch.rand(n, 3, generator=gen, dtype=dtype) * 2 - 1) * spread
    quats = torch.randn(n, 4, generator=gen, dtype=dtype) * 2  # unnormalised on purpose
    scales = torch.exp(torch.rand(n, 3, generator=gen, dtype=dtype) * 3 - 4.5)  # 0.011 .. 0.22
    opac = torch.rand(n, generator=gen, dtype=dtype) * 0.98 + 0.01
    sh = torch.randn(n, (sh_degree + 1) ** 2, 3, generator=gen, dtype=dtype) * 0.4
    return means, quats, scales, opac, sh


def random_camera(gen, **kw):
    d = torch.randn(3, generator=gen, dtype=torch.float64)
    eye = (d / d.norm() * 3.0).tolist()
    off = (torch.rand(2, generator=gen, dtype=torch.float64) - 0.5) * 4  # principal point off centre
    return look_at_camera(eye, cx=12 + off[0].item(), cy=10 + off[1].item(), **kw)


def single_gaussian(mean, scale=1e-3, opacity=0.99, rgb=(1.0, 1.0, 1.0), dtype=torch.float64):
    means = torch.tensor([mean], dtype=dtype)
    quats = torch.tensor([[1.0, 0.0, 0.0, 0.0]], dtype=dtype)
    scales = torch.full((1, 3), scale, dtype=dtype)
    opac = torch.tensor([opacity], dtype=dtype)
    sh = rgb_to_sh0(torch.tensor(rgb, dtype=dtype)).reshape(1, 1, 3)
    return means, quats, scales, opac, sh


def dense_opaque_scene(seed, n=60, sh_degree=1):
    gen = torch.Generator().manual_seed(seed)
    means, quats, scales, opac, sh = random_scene(gen, n, sh_degree, spread=0.3)
    opac = 0.5 + 0.49 * torch.rand(n, generator=gen, dtype=torch.float64)
    return means, quats, scales * 2, opac, sh


def level_grid(half, n, y):
    """(n*n, 3) points of a square grid [-half, half]^2 in the horizontal plane at height y."""
    xs = torch.linspace(-half, half, n)
    X, Z = torch.meshgrid(xs, xs, indexing="ij")
    return torch.stack([X.reshape(-1), torch.full((X.numel(),), float(y)), Z.reshape(-1)], 1)


def axis_splats(means, scales, opacity_logit=4.0):
    """Unrotated Gaussians at means with (N, 3) or (3,) scales, one opacity logit, black degree-0 SH."""
    n = len(means)
    scales = torch.as_tensor(scales, dtype=torch.float32).expand(n, 3)
    return Gaussians(means, torch.tensor([[1.0, 0.0, 0.0, 0.0]]).expand(n, 4).contiguous(), torch.log(scales),
                     torch.full((n,), float(opacity_logit)), torch.zeros(n, 1, 3))


def pass_views(g, albedo, normal, gloss, antialiased=False):
    """Five 64 px ring views (azimuth -30..30 deg, orbit centre (0, 1, 0)) of Gaussians g whose
    render passes are composited from known channels: (Views, {"albedo", "normal", "gloss"}:
    stacked targets), for the relight fit (patch fit.load_pass_targets to return the targets).
    normal may be a function of the camera (view-dependent normals) -> (N, 3)."""
    from splatting.raster.camera import ring_camera
    from splatting.relight.render import composite_features, prepare
    from splatting.training.views import Views

    cams = [ring_camera(a, orbit_centre=(0, 1, 0), size=64, focal=2084.97 * 64 / 512 * 2, name=f"camera{i:04d}")
            for i, a in enumerate((-30, -15, 0, 15, 30))]
    targets, imgs = {"albedo": [], "normal": [], "gloss": []}, []
    for c in cams:
        nrm = normal(c) if callable(normal) else normal
        (a, n, gl), alpha = composite_features(prepare(g, c, antialiased), [albedo, nrm, gloss])
        for k, x in zip(("albedo", "normal", "gloss"), (a, n, gl)):
            targets[k].append(x)
        imgs.append(torch.cat([a, alpha[..., None]], -1))
    views = Views(cams, torch.stack(imgs), [c.name for c in cams], "<memory>")
    return views, {k: torch.stack(x) for k, x in targets.items()}


def random_relight_files(plys, seed=0):
    """A relight file beside each PLY: albedo, gloss, unit normals (random: what matters here is
    that they are read, posed and shaded, not that they look like a bike)."""
    from cyclist_formats import bike_folder
    from splatting.gaussians.container import read_ply
    g = torch.Generator().manual_seed(seed)
    for ply in plys:
        n = len(read_ply(ply))
        nrm = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
        bike_folder.write_relight(ply, torch.rand(n, 3, generator=g).numpy() * 0.8, nrm.numpy(),
                                  torch.rand(n, 3, generator=g).numpy() * 0.1)


def kill_and_resume(generate, cfg, whole, resumed, removed, compared, generated):
    """A killed run resumed: `resumed` generated in full, the `removed` files (relative paths) deleted,
    generated again (it must redo `generated` samples); then every `compared` file is byte for byte
    the one in `whole`, a run never interrupted."""
    generate(cfg, resumed, log=lambda m: None, progress=False)
    for rel in removed:
        os.remove(os.path.join(resumed, rel))
    r = generate(cfg, resumed, log=lambda m: None, progress=False)
    assert r["generated"] == generated
    for rel in compared:
        with open(os.path.join(whole, rel), "rb") as f, open(os.path.join(resumed, rel), "rb") as g:
            assert f.read() == g.read(), rel


def with_blocks(cfg, **kw):
    """cfg (a plain config dict) with each keyword merged in: a dict into the block of that name,
    anything else set as is."""
    for k, v in kw.items():
        cfg[k] = dict(cfg.get(k, {}), **v) if isinstance(v, dict) and isinstance(cfg.get(k), dict) else v
    return cfg


def resolved(cfg):
    """The validated config with its assets resolved (one torch thread: the shared cores)."""
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.config import resolve_assets, validate
    return resolve_assets(validate(cfg))

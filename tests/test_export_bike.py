"""Articulated export (blender_scripts/export_bike.py): URDF in a real simulator, glTF reloaded.

The reference is `python -m splatting pose-bike`, which poses the bike's keypoints by docs/contract.md's
8-DoF pose; the exports must put the handle and pedal keypoints in the same places (1 mm) when
their joints are set to (theta_s, theta_p).  URDF frame = Blender frame = canonical (X, -Z, Y).
"""
import json
import math
import os
import struct
import subprocess
import sys

import numpy as np
import pytest
import torch

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXPORT = os.path.join(ROOT, "blender_scripts", "export_bike.py")
MAKE = os.path.join(ROOT, "blender_scripts", "make_bikes.py")
MOVING = ("handle_left", "handle_right", "front_axle", "pedal_left", "pedal_right")
POSES = [(0.0, 0.0), (90.0, 25.0), (-137.0, -40.0), (400.0, 70.0), (33.0, -85.0)]  # (theta_p, theta_s) deg
CLIP_KEYS = (3, 9, 22)  # glTF clip keys checked: theta_p = 10 k deg, theta_s = 20 sin(theta_p) deg
ALL_POSES = POSES + [(10.0 * k, 20.0 * math.sin(math.radians(10.0 * k))) for k in CLIP_KEYS]


def to_urdf(p):
    p = np.asarray(p, float)
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)


def run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=300, **kw)


@pytest.fixture(scope="module")
def bike(tmp_path_factory):
    pytest.importorskip("bpy")
    root = tmp_path_factory.mktemp("export")
    r = run([sys.executable, MAKE, "--out", str(root), "--count", "1", "--no-extras", "--seed", "3"])
    assert r.returncode == 0, r.stderr[-2000:]
    (bike_dir,) = [root / "bikes" / d for d in os.listdir(root / "bikes")]
    # pose-bike needs part Gaussians; their content does not move keypoints, so a few will do
    from splatting.gaussians.container import Gaussians, write_ply

    (bike_dir / "gaussians").mkdir()
    for part in ("frame", "steering", "crank"):
        n = 4
        write_ply(Gaussians(means=torch.randn(n, 3) * 0.1, quats=torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                            log_scales=torch.full((n, 3), -4.0), opacity_logits=torch.zeros(n),
                            sh=torch.zeros(n, 1, 3)), bike_dir / "gaussians" / f"{part}.ply")
    (root / "poses.json").write_text(json.dumps([[p, s, 0, 0, 0, 0, 0, 0] for p, s in ALL_POSES]))
    r = run([sys.executable, "-m", "splatting", "pose-bike", "--bike", str(bike_dir), "--poses",
             str(root / "poses.json"), "--out", str(root / "posed")])
    assert r.returncode == 0, r.stderr[-2000:]
    ref = [json.loads((root / "posed" / f"pose_{i:05d}.json").read_text())["keypoints"] for i in range(len(ALL_POSES))]
    out = {}
    for fmt, dest in (("urdf", root / "urdf"), ("gltf", root / "bike.glb")):
        r = run([sys.executable, EXPORT, "--bike", str(bike_dir), "--format", fmt, "--out", str(dest)])
        assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
        out[fmt] = dest
    return {"dir": bike_dir, "ref": ref, "root": root, **out,
            "keypoints": json.loads((bike_dir / "keypoints.json").read_text())["keypoints"]}


def test_urdf_in_pybullet_matches_pose_bike(bike):
    pb = pytest.importorskip("pybullet")
    (urdf,) = [p for p in os.listdir(bike["urdf"]) if p.endswith(".urdf")]
    sites = json.loads((bike["urdf"] / "keypoints.json").read_text())["keypoints"]
    cid = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(str(bike["urdf"] / urdf), useFixedBase=True, physicsClientId=cid)
        info = {pb.getJointInfo(body, i, physicsClientId=cid)[1].decode(): pb.getJointInfo(body, i, physicsClientId=cid)
                for i in range(pb.getNumJoints(body, physicsClientId=cid))}
        assert sorted(info) == ["crank", "steering"]
        assert info["steering"][8:10] == pytest.approx((-math.pi / 2, math.pi / 2))  # +-90 deg limits
        assert info["crank"][9] < info["crank"][8]  # continuous: pybullet's "no limit"
        assert {info[j][12].decode() for j in info} == {"steering", "crank"}
        worst = 0.0
        for (tp, ts), ref in zip(POSES, bike["ref"]):
            pb.resetJointState(body, info["steering"][0], math.radians(ts), physicsClientId=cid)
            pb.resetJointState(body, info["crank"][0], math.radians(tp), physicsClientId=cid)
            for k in MOVING:
                link = info[sites[k]["link"]][0]
                st = pb.getLinkState(body, link, computeForwardKinematics=True, physicsClientId=cid)
                R = np.array(pb.getMatrixFromQuaternion(st[5])).reshape(3, 3)
                got = R @ np.array(sites[k]["xyz"]) + np.array(st[4])
                err = np.linalg.norm(got - to_urdf(ref[k]))
                worst = max(worst, err)
                assert err < 1e-3, (tp, ts, k, got, to_urdf(ref[k]))
        assert worst < 1e-5  # in fact exact up to float printing
        # the rest pose moved something: the check is not vacuous
        assert np.linalg.norm(np.array(bike["ref"][1]["pedal_left"]) - bike["keypoints"]["pedal_left"]) > 0.1
        # inertials: the crank's shells are all closed, so its mass is density x its volume (trimesh)
        import trimesh
        crank = trimesh.load(bike["urdf"] / "meshes" / "crank.obj", force="mesh", process=True)
        vol = sum(abs(c.volume) for c in crank.split(only_watertight=False))
        assert pb.getDynamicsInfo(body, info["crank"][0], physicsClientId=cid)[0] == pytest.approx(1000.0 * vol, rel=1e-4)
        assert 3.0 < sum(pb.getDynamicsInfo(body, info[j][0], physicsClientId=cid)[0] for j in info) + \
            json.loads((bike["urdf"] / "keypoints.json").read_text())["mass_kg"]["frame"] < 40.0
    finally:
        pb.disconnect(cid)


def _glb(path):
    data = path.read_bytes()
    magic, version, total = struct.unpack_from("<III", data)
    assert (magic, version, total) == (0x46546C67, 2, len(data))
    n, kind = struct.unpack_from("<II", data, 12)
    assert kind == 0x4E4F534A
    doc = json.loads(data[20:20 + n])
    m, kind = struct.unpack_from("<II", data, 20 + n)
    assert kind == 0x004E4942
    return doc, data[28 + n:28 + n + m]


def _accessor(doc, binary, i):
    a = doc["accessors"][i]
    v = doc["bufferViews"][a["bufferView"]]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[a["type"]]
    dt = {5126: np.float32, 5125: np.uint32}[a["componentType"]]
    return np.frombuffer(binary, dt, a["count"] * width, v["byteOffset"]).reshape(a["count"], width)


def test_gltf_reloads_with_pivots_in_place(bike, fresh_scene):
    import trimesh

    s = trimesh.load(bike["gltf"], force="scene")
    kp = {k: np.array(v) for k, v in bike["keypoints"].items()}
    np.testing.assert_allclose(s.graph.get("steering")[0][:3, 3], kp["steer_bottom"], atol=1e-6)
    np.testing.assert_allclose(s.graph.get("crank")[0][:3, 3], kp["crank_axle"], atol=1e-6)
    for k, v in kp.items():
        np.testing.assert_allclose(s.graph.get(f"kp_{k}")[0][:3, 3], v, atol=1e-6)
    # each part's geometry, placed by the scene graph, covers what bike.blend's object covers
    import bpy
    from addon.core.frames import to_canonical

    bpy.ops.wm.open_mainfile(filepath=str(bike["dir"] / "bike.blend"))
    for part in ("frame", "steering", "crank"):
        o = bpy.data.objects[part]
        co = np.array([(o.matrix_world @ v.co)[:] for v in o.data.vertices])
        ref = to_canonical(co)
        pts = []
        for node in s.graph.nodes_geometry:
            T, g = s.graph.get(node)
            if node.startswith(part + "_"):  # trimesh names a primitive's node <mesh name>_<hash>
                pts.append(trimesh.transform_points(s.geometry[g].vertices, T))
        assert pts, (part, list(s.graph.nodes_geometry))
        got = np.concatenate(pts)
        np.testing.assert_allclose(got.min(0), ref.min(0), atol=1e-5)
        np.testing.assert_allclose(got.max(0), ref.max(0), atol=1e-5)


def test_gltf_clip_poses_like_pose_bike(bike):
    doc, binary = _glb(bike["gltf"])
    (anim,) = doc["animations"]
    tp, ts = np.array(anim["extras"]["theta_p_deg"]), np.array(anim["extras"]["theta_s_deg"])
    k = np.arange(len(tp))
    np.testing.assert_allclose(tp, 10.0 * k, atol=1e-9)  # the documented clip: one crank turn
    np.testing.assert_allclose(ts, 20.0 * np.sin(np.radians(10.0 * k)), atol=1e-9)
    names = [n["name"] for n in doc["nodes"]]
    rot = {}
    for ch in anim["channels"]:
        smp = anim["samplers"][ch["sampler"]]
        assert ch["target"]["path"] == "rotation" and smp["interpolation"] == "LINEAR"
        rot[names[ch["target"]["node"]]] = _accessor(doc, binary, smp["output"])
    times = _accessor(doc, binary, anim["samplers"][0]["input"])[:, 0]
    assert times[0] == 0 and times[-1] == pytest.approx(2.0)
    kp = {n: np.array(v) for n, v in bike["keypoints"].items()}
    pivot = {"steering": kp["steer_bottom"], "crank": kp["crank_axle"]}
    part_of = {"handle_left": "steering", "handle_right": "steering", "front_axle": "steering",
               "pedal_left": "crank", "pedal_right": "crank"}
    for j, key in enumerate(CLIP_KEYS):
        ref = bike["ref"][len(POSES) + j]
        for name, part in part_of.items():
            x, y, z, w = (float(c) for c in rot[part][key])
            R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                          [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                          [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
            got = pivot[part] + R @ (kp[name] - pivot[part])  # node: T(pivot) R, mesh stored pivot-relative
            assert np.linalg.norm(got - ref[name]) < 1e-3, (key, name, got, ref[name])


def test_bad_input_one_line_nothing_written(tmp_path, bike):
    cases = [["--bike", str(tmp_path / "nope"), "--format", "urdf", "--out", str(tmp_path / "o")],
             ["--bike", str(bike["dir"]), "--format", "gltf", "--out", str(tmp_path / "o.gltf")],
             ["--bike", str(bike["dir"]), "--format", "urdf", "--out", str(tmp_path / "o"), "--density", "nan"],
             ["--bike", str(bike["dir"]), "--format", "obj", "--out", str(tmp_path / "o")]]
    for args in cases:
        r = run([sys.executable, EXPORT, *args])
        assert r.returncode == 2, (args, r.stderr)
        assert "Traceback" not in r.stderr and len([ln for ln in r.stderr.splitlines() if "error" in ln]) == 1, r.stderr
    assert list(tmp_path.iterdir()) == []
    broken = tmp_path / "broken"
    broken.mkdir()
    for f in ("bike.blend", "meta.json"):
        (broken / f).write_bytes((bike["dir"] / f).read_bytes())
    (broken / "keypoints.json").write_text('{"keypoints": {"steer_top": [0, 1, 0], "steer_bottom": [0, 1, 0]}}')
    r = run([sys.executable, EXPORT, "--bike", str(broken), "--format", "urdf", "--out", str(tmp_path / "o")])
    assert r.returncode == 2 and "lacks keypoints crank_axle" in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken"]


def test_mass_properties_box_and_inward_shell():
    """A box (analytic inertia) plus a sphere wound inward: both count positively; trimesh agrees."""
    import trimesh

    from addon.core.export.mass import mass_properties

    box = trimesh.creation.box((0.2, 0.4, 1.0))
    box.apply_translation((1.0, 2.0, 3.0))
    ball = trimesh.creation.icosphere(2, 0.3)
    ball.apply_translation((-1.0, 0.0, 0.0))
    inward = ball.copy()
    inward.invert()
    both = trimesh.util.concatenate([box, inward])
    p = mass_properties(both.vertices, both.faces, 1000.0)
    assert (p.shells, p.open_shells) == (2, 0)
    assert p.volume == pytest.approx(0.08 + ball.volume, rel=1e-9)
    ref = trimesh.util.concatenate([box, ball])
    ref.density = 1000.0
    np.testing.assert_allclose(p.com, ref.center_mass, atol=1e-9)
    np.testing.assert_allclose(p.inertia, ref.moment_inertia, atol=1e-9)
    only_box = mass_properties(box.vertices, box.faces, 1000.0)
    m = 80.0  # kg: 0.08 m^3 at 1000 kg/m^3; I_xx = m (b^2 + c^2) / 12 about the centre
    np.testing.assert_allclose(np.diag(only_box.inertia), [m * (0.16 + 1) / 12, m * (0.04 + 1) / 12, m * (0.04 + 0.16) / 12])
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-2])  # one face missing: no inside
    with pytest.raises(ValueError):
        mass_properties(open_box.vertices, open_box.faces, 1000.0)
    pytest.importorskip("bpy")
    from addon.core.export.parts import convex_hull  # bmesh's, as the exporter uses it

    ph = mass_properties(open_box.vertices, open_box.faces, 1000.0, hull=convex_hull)
    assert (ph.shells, ph.open_shells) == (0, 1) and ph.volume == pytest.approx(0.08)

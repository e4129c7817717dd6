"""Curation: numpy geometry (fast, no bpy), the add-on's operators headless (bpy 5.0 module),
curate.py's bad-input contract, and render_views.py on a curated bike."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from addon.core.curation import mesh, pipeline, split, wheels
from addon.core.curation.validate import validate
from addon.core.procedural import build, layout, spec as specs
from addon.core.script import UserError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CURATE = os.path.join(ROOT, "blender_scripts", "curate.py")


def _fan(faces):
    return np.array([(f[0], f[i], f[i + 1]) for f in faces for i in range(1, len(f) - 1)])


def _bike_arrays(sp):
    _, b = build.part_builders(sp)
    V, T, lab, off = [], [], [], 0
    for k, (name, mb) in enumerate(b.items()):
        t = _fan(mb.faces)
        V.append(mb.vertices)
        T.append(t + off)
        lab += [k] * len(t)
        off += len(mb.vertices)
    return np.concatenate(V), np.concatenate(T), np.array(lab)


# ------------------------------------------------------------------ numpy, fast

def test_weld_and_components_ignore_split_vertices():
    # two triangles sharing an edge but with duplicated vertices (as glTF stores flat faces)
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 5, 5], [6, 5, 5], [5, 6, 5]], float)
    T = np.array([[0, 1, 2], [3, 5, 4], [6, 7, 8]])
    s = mesh.Soup(V, T)
    assert len(s.P) == 7
    assert len(s.comps) == 2
    assert sorted(len(c.tris) for c in s.comps) == [1, 2]


def test_ring_fit_torus_and_rejects_square():
    a = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    b = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    R, r = 0.33, 0.015
    pts = np.array([[(R - r + r * np.cos(j)) * np.cos(i), (R - r + r * np.cos(j)) * np.sin(i), r * np.sin(j)]
                    for i in a for j in b]) + [1.0, 2.0, 3.0]
    ring = wheels.ring_of(pts)
    assert ring is not None
    assert abs(ring.radius - R) < 1e-3 and np.allclose(ring.centre, [1, 2, 3], atol=1e-6)
    assert abs(abs(ring.normal[2]) - 1) < 1e-9
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 20), np.linspace(-1, 1, 20)), -1).reshape(-1, 2)
    assert wheels.ring_of(np.column_stack([g, np.zeros(len(g))])) is None  # a ground grid


@pytest.mark.parametrize("style_index", [0, 3])  # road (drop bar), bmx
def test_curate_arrays_recovers_pose_keypoints_parts(style_index):
    sp = specs.library_specs(7, 2, extras=False)[style_index]
    V, T, lab = _bike_arrays(sp)
    rng = np.random.default_rng(style_index)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    s = 42.0
    res = pipeline.curate_arrays(s * V @ q.T + [3, -2, 7], T, sp["wheel_diameter_m"])
    Rm = res.M[:3, :3] / res.scale
    assert np.degrees(np.arccos(np.clip((np.trace(Rm @ q) - 1) / 2, -1, 1))) < 0.01
    assert abs(res.scale * s - 1) < 1e-6
    truth = layout.keypoints(sp)
    err = {k: np.linalg.norm(res.keypoints[k] - truth[k]) for k in truth}
    assert max(err.values()) < 0.01, err
    area = mesh.triangle_areas(V, T)
    assert area[res.labels == lab].sum() / area.sum() > 0.98
    assert res.problems == []


def test_no_wheels_is_a_user_error():
    from addon.core.procedural.meshkit import box
    v, f = box([0, 0, 0], [1, 2, 3])
    with pytest.raises(UserError, match="no wheels found"):
        pipeline.curate_arrays(v, _fan(f))


def test_validate_names_the_failing_keypoint():
    sp = specs.library_specs(1, 0, extras=False)[0]
    kp = {k: np.array(v) for k, v in layout.keypoints(sp).items()}
    assert validate(kp) == []
    bad = dict(kp, steer_top=kp["steer_bottom"] + [0, 0.001, 0])
    assert any(p.startswith("steer_top:") and "degenerate" in p for p in validate(bad))
    bad = dict(kp, handle_left=kp["handle_right"])
    assert any(p.startswith("handle_left:") for p in validate(bad))
    bad = dict(kp, seat=kp["crank_axle"] - [0, 0.1, 0])
    assert any(p.startswith("seat:") for p in validate(bad))
    bad = dict(kp, pedal_left=kp["pedal_right"])
    assert any(p.startswith("pedal_left:") for p in validate(bad))
    bad = dict(kp)
    del bad["ground"]
    assert validate(bad) == ["ground: missing"]


def test_regions_put_steerer_on_steering_and_head_tube_wall_on_frame():
    sp = specs.library_specs(1, 0, extras=False)[0]
    kp = {k: np.array(v) for k, v in layout.keypoints(sp).items()}
    a = kp["steer_top"] - kp["steer_bottom"]
    a /= np.linalg.norm(a)
    mid = 0.5 * (kp["steer_top"] + kp["steer_bottom"])
    side = np.cross(a, [0, 0, 1.0])
    pts = np.array([mid + 0.01 * side, mid + 0.021 * side, kp["pedal_right"], kp["crank_axle"] + [0, 0.021, 0.02],  # BB shell wall
                    kp["front_axle"] + [0, 0.2, 0], kp["seat"]])
    got = split.regions(pts, kp, head_radius=0.021)
    assert list(got) == [split.STEERING, split.FRAME, split.CRANK, split.FRAME, split.STEERING, split.FRAME]


# ------------------------------------------------------------------ operators headless (bpy 5.0)

@pytest.fixture
def messy(tmp_path, fresh_scene):
    from blender_helpers import make_messy
    sp = specs.library_specs(2, 4, extras=False)[1]
    path = tmp_path / "messy.glb"
    make_messy(sp, np.random.default_rng(11), path, "glb")
    from addon.core.scene import reset_scene
    reset_scene()
    return path, sp


def _register(bpy):
    import addon
    if not hasattr(bpy.types.Scene, "articcyc_wheel_diameter"):
        addon.register()


def test_operators_headless_edit_resplit_save(messy, tmp_path):
    import bpy
    from addon.core.curation import scene_state
    path, sp = messy
    _register(bpy)
    assert bpy.ops.articcyc.import_model(filepath=str(path)) == {"FINISHED"}
    assert bpy.ops.articcyc.auto_curate(wheel_diameter=sp["wheel_diameter_m"]) == {"FINISHED"}
    assert bpy.ops.articcyc.validate() == {"FINISHED"}
    assert len(bpy.context.scene.articcyc_problems) == 0
    n_steer = len(bpy.data.objects["steering"].data.polygons)
    # annotator: drag a keypoint away -> Validate names it
    e = bpy.data.objects["kp.handle_left"]
    e.location.z -= 0.3
    bpy.ops.articcyc.validate()
    assert any(p.name.startswith("handle_left") for p in bpy.context.scene.articcyc_problems)
    e.location.z += 0.3
    # annotator: paint every face of the source as frame, re-split -> no steering -> error
    src = bpy.data.objects[scene_state.SOURCE]
    src.data.polygons.foreach_set("select", [True] * len(src.data.polygons))
    assert bpy.ops.articcyc.paint_part(part="frame") == {"FINISHED"}
    with pytest.raises(RuntimeError, match="no steering"):
        bpy.ops.articcyc.split_parts()
    scene_state.face_attr(src.data, scene_state.PAINT_ATTR, np.full(len(src.data.polygons), -1))
    assert bpy.ops.articcyc.split_parts() == {"FINISHED"}  # recomputed from the keypoints
    assert len(bpy.data.objects["steering"].data.polygons) == n_steer
    assert bpy.ops.articcyc.build_rig() == {"FINISHED"}
    bpy.context.scene.articcyc_theta_s_deg = 30.0
    assert abs(bpy.data.objects["armature"].pose.bones["steering"].rotation_euler[1] - np.radians(30)) < 1e-6
    out = tmp_path / "bikes" / "curated"
    assert bpy.ops.articcyc.save_bike(directory=str(out)) == {"FINISHED"}
    assert sorted(os.listdir(out)) == ["bike.blend", "keypoints.json", "meta.json"]
    assert not [d for d in os.listdir(out.parent) if d.startswith(".")]
    from addon.core.bike_asset import open_bike
    bike = open_bike(str(out))
    assert sorted(o.name for o in bpy.data.objects) == ["armature", "crank", "frame", "steering"]
    assert {n: o.pass_index for n, o in bike["parts"].items()} == {"frame": 1, "steering": 2, "crank": 3}
    meta = json.loads((out / "meta.json").read_text())
    assert meta["generator"] == "curated" and meta["curation"]["problems"] == []
    kp = json.loads((out / "keypoints.json").read_text())
    assert set(kp["parts"]) == {"frame", "steering", "crank"}
    truth = layout.keypoints(sp)
    assert max(np.linalg.norm(np.array(kp["keypoints"][k]) - truth[k]) for k in truth) < 0.01


def _run(*args):
    return subprocess.run([sys.executable, CURATE, *args], capture_output=True, text=True, cwd=ROOT, timeout=300)


def test_curate_bad_inputs_one_line_nothing_written(tmp_path):
    out = tmp_path / "bikes" / "x"
    (tmp_path / "corrupt.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
    (tmp_path / "empty.obj").write_text("# nothing\n")
    (tmp_path / "cube.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n")
    (tmp_path / "model.xyz").write_text("1 2 3\n")
    cases = {"missing.glb": "not found", "corrupt.glb": "cannot import", "empty.obj": "no objects",
             "cube.obj": "no wheels found", "model.xyz": "unsupported"}
    for name, needle in cases.items():
        r = _run("--input", str(tmp_path / name), "--out", str(out))
        err = [ln for ln in r.stderr.splitlines() if ln.startswith("curate.py: error:")]
        assert r.returncode == 2, (name, r.stderr[-2000:])
        assert len(err) == 1 and needle in err[0], (name, r.stderr[-2000:])
        assert not (tmp_path / "bikes").exists() or not os.listdir(tmp_path / "bikes"), name
    r = _run("--input", str(tmp_path / "cube.obj"), "--out", str(out), "--wheel-diameter", "-1")
    assert r.returncode == 2 and "wheel-diameter" in r.stderr


def test_curated_bike_renders_and_keypoints_land_on_masks(messy, tmp_path):
    """curate.py then render_views.py unchanged, with render_views' own keypoint-on-mask check."""
    path, sp = messy
    out = tmp_path / "bikes" / "cur"
    r = _run("--input", str(path), "--out", str(out), "--wheel-diameter", str(sp["wheel_diameter_m"]))
    assert r.returncode == 0, r.stderr[-2000:]
    rv = subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "render_views.py"), "--bike", str(out),
                         "--parts", "all", "--views", "0,9,22", "--samples", "1", "--denoise", "NONE"],
                        capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert rv.returncode == 0, rv.stderr[-2000:]
    from blender_helpers import check_keypoints_on_masks
    subs = json.loads((out / "meta.json").read_text())["sub_parts"]  # curate.py cuts out the wheels and pedals
    assert {"front_wheel", "rear_wheel"} <= set(subs), subs
    for part in ("frame", "steering", "crank", *subs, "whole"):
        check_keypoints_on_masks(out / "views" / part, [0, 9, 22])

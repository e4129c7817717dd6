"""Procedural bike library: spec ranges, determinism, keypoints on their parts, Blender scenes,
bike folders (make_bikes under the bpy module and, marked, the Debian Blender binary)."""
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from addon.core.procedural import layout
from addon.core.procedural import spec as specs
from addon.core.script import UserError
from ci_needs import missing

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MAKE = os.path.join(ROOT, "blender_scripts", "make_bikes.py")
PY = sys.executable


@pytest.fixture(scope="module")
def library():
    return specs.library_specs(23, 0)


def _bicycles(lib):
    return [s for s in lib if s["rideable"] == "bicycle"]


def test_library_has_23_distinct_bicycles_over_5_styles_plus_extras(library):
    bikes = _bicycles(library)
    assert len(bikes) == 23
    assert len({s["style"] for s in bikes}) >= 5
    ids = [s["bike_id"] for s in library]
    assert len(set(ids)) == len(ids) == 25
    assert {s["rideable"] for s in library} == {"bicycle", "kick_scooter", "motorcycle"}
    assert "scooter" in " ".join(ids) and "motorcycle_00" in ids
    # distinct geometry, not just distinct names
    sig = {(round(s["wheel_diameter_m"], 4), round(s["wheelbase_m"], 4), round(s["head_angle_deg"], 3))
           for s in bikes}
    assert len(sig) == 23


def test_specs_deterministic_per_seed_and_independent_of_count(library):
    again = specs.library_specs(23, 0)
    assert json.dumps(again, sort_keys=True) == json.dumps(library, sort_keys=True)
    other = specs.library_specs(23, 1)
    assert json.dumps(other, sort_keys=True) != json.dumps(library, sort_keys=True)
    # road_00 is the same bike whatever --count is (resumable, extendable libraries)
    assert specs.library_specs(3, 0, extras=False)[0] == library[0]


def test_bicycle_dimensions_in_real_ranges(library):
    for s in _bicycles(library):
        kp = layout.keypoints(s)
        fa, ra = np.array(kp["front_axle"]), np.array(kp["rear_axle"])
        d = 2 * fa[1]  # axle height = wheel radius when the tyre touches Y=0
        assert 0.40 <= d <= 0.74, s["bike_id"]
        assert 0.85 <= fa[0] - ra[0] <= 1.25, s["bike_id"]
        v = np.array(kp["steer_top"]) - np.array(kp["steer_bottom"])
        head = np.degrees(np.arctan2(v[1], -v[0]))
        assert 66.0 <= head <= 75.0, (s["bike_id"], head)
        L = layout.bicycle_layout(s)
        st = L["saddle_top"] - L["bb"]
        seat = np.degrees(np.arctan2(st[1], -st[0]))
        assert 70.0 <= seat <= 75.0, (s["bike_id"], seat)
        assert 0.26 <= kp["crank_axle"][1] <= 0.32, s["bike_id"]


def test_keypoint_frame_conventions(library):
    for s in library:
        kp = {k: np.array(v) for k, v in layout.keypoints(s).items()}
        assert set(kp) == set(layout.KEYPOINT_NAMES)
        ca = kp["crank_axle"]
        assert ca[0] == 0.0 and ca[2] == 0.0 and ca[1] > 0, s["bike_id"]   # on the Y axis
        assert np.allclose(kp["handle_left"], kp["handle_right"] * [1, 1, -1]), s["bike_id"]
        assert kp["handle_left"][2] < 0 < kp["handle_right"][2]          # left = -Z
        for name in ("seat", "steer_top", "steer_bottom", "front_axle", "rear_axle", "ground", "crank_axle"):
            assert kp[name][2] == 0.0, (s["bike_id"], name)
        assert np.allclose(kp["ground"], [kp["rear_axle"][0], 0, 0])
        assert kp["front_axle"][0] > 0 > kp["rear_axle"][0]
        assert kp["steer_top"][1] > kp["steer_bottom"][1] and kp["steer_top"][0] < kp["steer_bottom"][0]
        if s["rideable"] == "bicycle":
            # right crank forward and horizontal, left backward (point reflection through the axle)
            pr, pl = kp["pedal_right"] - ca, kp["pedal_left"] - ca
            assert pr[0] > 0.1 and abs(pr[1]) < 1e-12 and pr[2] > 0
            assert np.allclose(pl, -pr)
        else:
            assert np.allclose(kp["pedal_left"], kp["pedal_right"] * [1, 1, -1])


def _line_hits(tris, origin, d):
    """Does the infinite line origin + t d hit any triangle (Moller-Trumbore, vectorised)?"""
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    return bool(np.any(ok & (u >= 0) & (v >= 0) & (u + v <= 1)))


def _triangles(mb):
    v = mb.vertices
    tris = []
    for f in mb.faces:
        for k in range(1, len(f) - 1):
            tris.append((f[0], f[k], f[k + 1]))
    return v[np.array(tris)]


def test_keypoints_lie_on_their_parts_in_every_ring_view(library):
    """Like the renderer's mask check: from each of 36 horizontal view directions, the line of
    sight through a keypoint (or one within 5 mm of it) meets that part's surface."""
    from addon.core.procedural.build import part_builders

    dirs = [np.array([np.sin(a), 0.0, np.cos(a)]) for a in np.radians(np.arange(0, 360, 10))]
    picks = {s["style"]: s for s in library}  # one bike per style and the two extras
    for s in picks.values():
        _, builders = part_builders(s)
        kp = layout.keypoints(s)
        for part, names in layout.part_keypoints(s).items():
            tris = _triangles(builders[part])
            for name in names:
                p = np.array(kp[name])
                for d in dirs:
                    up = np.array([0, 1.0, 0])
                    side = np.cross(d, up)
                    cands = [p] + [p + 0.005 * e for e in (up, -up, side, -side)]
                    assert any(_line_hits(tris, c, d) for c in cands), (s["bike_id"], part, name, d)


def test_geometry_is_deterministic_and_bikes_differ(library):
    from addon.core.procedural.build import part_builders

    a = part_builders(library[0])[1]["frame"].vertices
    b = part_builders(specs.sample_spec("road", 0, 0))[1]["frame"].vertices
    c = part_builders(library[7])[1]["frame"].vertices  # road_01
    assert np.array_equal(a, b)
    assert a.shape != c.shape or not np.allclose(a, c)


# ------------------------------------------------------------------ Blender scenes

BUILD_STYLES = ["road", "bmx", "kick_scooter", "motorcycle"]


@pytest.mark.parametrize("style", BUILD_STYLES)
def test_build_bike_scene_contract(fresh_scene, style):
    import bpy
    from addon.core.frames import to_canonical
    from addon.core.procedural.build import build_bike

    s = specs.sample_spec(style, 0, 0)
    res = build_bike(s)
    names = ["frame", "steering"] + (["crank"] if s["rideable"] == "bicycle" else [])
    assert sorted(res["parts"]) == sorted(names)
    meshes = [o for o in bpy.data.objects if o.type == "MESH"]
    assert sorted(o.name for o in meshes) == sorted(names)
    for name, idx in (("frame", 1), ("steering", 2), ("crank", 3)):
        if name in names:
            assert bpy.data.objects[name].pass_index == idx
    arm = bpy.data.objects["armature"]
    assert arm.type == "ARMATURE"
    assert np.allclose(np.array(arm.matrix_world), np.eye(4))
    kp = res["keypoints"]
    tri_total = 0
    for name in names:
        obj = bpy.data.objects[name]
        me = obj.data
        me.calc_loop_triangles()
        tri_total += len(me.loop_triangles)
        v = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", v)
        mw = np.array(obj.matrix_world)
        v = v.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
        c = to_canonical(v)
        assert c[:, 1].min() > -1e-6, name   # nothing below the ground
        if name in ("frame", "steering"):
            axle = kp["rear_axle" if name == "frame" else "front_axle"]
            wheel = np.linalg.norm(c[:, :2] - np.array(axle)[:2], axis=1) < 0.5 * s["wheel_diameter_m"] + 1e-6
            assert abs(c[wheel, 1].min()) < 0.002, name   # the tyre touches Y = 0
            low = c[np.argmin(c[:, 1])]
            assert abs(low[0] - axle[0]) < 0.02, name      # ... right below its axle
    assert tri_total < 60000


def test_armature_bones(fresh_scene):
    import bpy
    from addon.core.frames import to_canonical
    from addon.core.procedural.build import build_bike

    s = specs.sample_spec("city", 0, 0)
    res = build_bike(s)
    bones = bpy.data.objects["armature"].data.bones
    kp = res["keypoints"]
    assert set(bones.keys()) == {"frame", "steering", "crank"} | set(layout.KEYPOINT_NAMES)
    h = lambda b: to_canonical(np.array(bones[b].head_local))  # noqa: E731
    t = lambda b: to_canonical(np.array(bones[b].tail_local))  # noqa: E731
    assert np.allclose(h("steering"), kp["steer_bottom"]) and np.allclose(t("steering"), kp["steer_top"])
    assert np.allclose(h("crank"), kp["crank_axle"])
    assert np.allclose(t("crank") - h("crank"), [0, 0, 0.1])
    for name in layout.KEYPOINT_NAMES:
        assert np.allclose(h(name), kp[name], atol=1e-6), name
        want = {"handle_left": "steering", "handle_right": "steering", "front_axle": "steering",
                "pedal_left": "crank", "pedal_right": "crank"}.get(name, "frame")
        assert bones[name].parent.name == want
    for part in ("frame", "steering", "crank"):
        obj = bpy.data.objects[part]
        assert obj.parent.name == "armature" and obj.parent_type == "BONE" and obj.parent_bone == part


def test_make_bikes_writes_resumable_folders(tmp_path):
    out = tmp_path / "lib"
    cmd = [PY, MAKE, "--out", str(out), "--count", "2", "--seed", "0", "--no-extras"]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    for bid in ("road_00", "mountain_00"):
        d = out / "bikes" / bid
        assert sorted(os.listdir(d)) == ["bike.blend", "keypoints.json", "meta.json"]
        kd = json.loads((d / "keypoints.json").read_text())
        assert kd["frame"] == "canonical" and kd["units"] == "m"
        assert set(kd["keypoints"]) == set(layout.KEYPOINT_NAMES)
        assert kd["parts"]["crank"] == ["crank_axle", "pedal_left", "pedal_right"]
        meta = json.loads((d / "meta.json").read_text())
        assert meta["bike_id"] == bid and meta["generator"] == "procedural" and meta["has_crank"] is True
        assert meta["rideable"] == "bicycle" and meta["seed"] == 0
        assert set(meta["triangles"]) == {"frame", "steering", "crank", *meta["sub_parts"]}
        assert meta["sub_parts"] == ["front_wheel", "rear_wheel", "pedal_left", "pedal_right"]
        assert 0.85 <= meta["dimensions"]["wheelbase_m"] <= 1.25
    mtime = os.path.getmtime(out / "bikes" / "road_00" / "bike.blend")
    os.remove(out / "bikes" / "mountain_00" / "meta.json")   # an interrupted bike
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "road_00: complete, skipped" in r.stdout
    assert "mountain_00: complete" not in r.stdout
    assert (out / "bikes" / "mountain_00" / "meta.json").exists()
    assert os.path.getmtime(out / "bikes" / "road_00" / "bike.blend") == mtime
    assert not [f for f in os.listdir(out / "bikes" / "mountain_00") if f.startswith(".")]


def test_make_bikes_bad_args_one_line(tmp_path):
    r = subprocess.run([PY, MAKE, "--out", str(tmp_path), "--count", "-1"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1].startswith("make_bikes: error: --count")
    assert not (tmp_path / "bikes").exists()


def test_open_bike_errors(fresh_scene, tmp_path):
    from addon.core.bike_asset import open_bike

    with pytest.raises(UserError, match="not found"):
        open_bike(tmp_path / "nope")
    d = tmp_path / "b"
    d.mkdir()
    with pytest.raises(UserError, match="missing"):
        open_bike(d)
    (d / "bike.blend").write_bytes(b"this is not a blend file")
    with pytest.raises(UserError, match="cannot open"):
        open_bike(d)


def test_save_and_open_bike_roundtrip(fresh_scene, tmp_path):
    import bpy
    from addon.core.bike_asset import open_bike, save_bike
    from addon.core.procedural.build import build_bike

    s = specs.sample_spec("kick_scooter", 0, 0)
    res = build_bike(s)
    save_bike(tmp_path / "kick_scooter_00", s, res["keypoints"], layout.part_keypoints(s), {"bike_id": "x"})
    bpy.ops.wm.read_factory_settings(use_empty=True)
    b = open_bike(tmp_path / "kick_scooter_00")
    assert sorted(b["parts"]) == ["frame", "steering"]
    assert b["armature"].name == "armature" and b["meta"] == {"bike_id": "x"}
    assert b["keypoints"]["seat"] == pytest.approx(res["keypoints"]["seat"])


@pytest.mark.blender_binary
def test_make_bikes_under_blender_34(tmp_path):
    blender = shutil.which("blender") or "/usr/bin/blender"
    if not os.path.exists(blender):
        missing("the Debian blender binary")
    out = tmp_path / "lib34"
    r = subprocess.run([blender, "-b", "--factory-startup", "-P", MAKE, "--", "--out", str(out), "--count", "1",
                        "--no-extras"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-2000:])
    meta = json.loads((out / "bikes" / "road_00" / "meta.json").read_text())
    assert meta["blender_version"].startswith("3.4")
    # same seed, same bike whichever Blender built it
    assert meta["spec"] == specs.sample_spec("road", 0, 0)

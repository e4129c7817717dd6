"""The armature's steering and crank bones move keypoints and part meshes exactly as docs/contract.md's
H_s, H_p and H_g say (expected values computed here in numpy, independently of the add-on)."""
import numpy as np
import pytest

from addon.core.procedural import layout
from addon.core.procedural import spec as specs

TOL = 1e-4  # metres


def rot_axis(axis, deg):
    """Rodrigues: right-hand rotation by deg about unit axis."""
    k = np.asarray(axis, float)
    k = k / np.linalg.norm(k)
    a = np.radians(deg)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def about(p, centre, R):
    return (np.asarray(p) - centre) @ R.T + centre


def expected(kp_rest, part_of, theta_p, theta_s, rot=(0, 0, 0), t=(0, 0, 0)):
    """Canonical positions after H_g . (H_s | H_p) for points tagged with their part."""
    sb, st = np.array(kp_rest["steer_bottom"]), np.array(kp_rest["steer_top"])
    Hs = rot_axis(st - sb, theta_s)
    ca = np.array(kp_rest["crank_axle"])
    Hp = rot_axis([0, 0, 1], -theta_p)
    Rg = rot_axis([0, 0, 1], rot[2]) @ rot_axis([0, 1, 0], rot[1]) @ rot_axis([1, 0, 0], rot[0])

    def f(p, part):
        p = np.asarray(p, float)
        if part == "steering":
            p = about(p, sb, Hs)
        elif part == "crank":
            p = about(p, ca, Hp)
        return p @ Rg.T + np.asarray(t, float)
    return f


def world_vertices(obj):
    import bpy
    from addon.core.frames import to_canonical

    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    me = ev.data
    v = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", v)
    mw = np.array(ev.matrix_world)
    return to_canonical(v.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3])


POSES = [(90, 30, (0, 0, 0), (0, 0, 0)), (-120, -40, (0, 0, 0), (0, 0, 0)),
         (35, 12.5, (5, -20, 10), (0.3, 0.1, -1.2)), (-10, -7, (0, 90, 0), (1, 0, 0))]


@pytest.mark.parametrize("style", ["road", "mountain", "motorcycle"])
def test_pose_matches_design_formula(fresh_scene, style):
    from addon.core.rig.articulation import apply_pose, posed_keypoints
    from addon.core.procedural.build import build_bike

    s = specs.sample_spec(style, 0, 0)
    res = build_bike(s)
    arm, parts = res["armature"], res["parts"]
    kp0 = res["keypoints"]
    rest = {name: world_vertices(obj) for name, obj in parts.items()}
    kp_rest_posed = posed_keypoints(arm)
    for k, v in kp0.items():
        assert np.allclose(kp_rest_posed[k], v, atol=1e-6), k
    for theta_p, theta_s, rot, t in POSES:
        apply_pose(arm, theta_p, theta_s, rot, t)
        f = expected(kp0, None, theta_p, theta_s, rot, t)
        got = posed_keypoints(arm)
        for name, p in kp0.items():
            part = layout.bone_parent(name, s)
            assert np.abs(np.array(got[name]) - f(p, part)).max() <= TOL, (style, name, theta_p, theta_s)
        for name, obj in parts.items():
            v = world_vertices(obj)
            assert np.abs(v - f(rest[name], name)).max() <= TOL, (style, name, theta_p, theta_s)
    apply_pose(arm, 0, 0)
    for name, obj in parts.items():
        assert np.abs(world_vertices(obj) - rest[name]).max() <= 1e-6


def test_sign_conventions(fresh_scene):
    from addon.core.rig.articulation import apply_pose, posed_keypoints
    from addon.core.procedural.build import build_bike

    s = specs.sample_spec("city", 0, 0)
    res = build_bike(s)
    arm, kp0 = res["armature"], res["keypoints"]
    apply_pose(arm, 0, 30)
    kp = posed_keypoints(arm)
    # +theta_s turns the front wheel to the rider's left (-Z); the right grip comes forward
    assert kp["front_axle"][2] < -0.01
    assert kp["handle_right"][0] > kp0["handle_right"][0] + 0.05
    assert kp["handle_left"][0] < kp0["handle_left"][0] - 0.05
    assert np.allclose(kp["seat"], kp0["seat"]) and np.allclose(kp["pedal_right"], kp0["pedal_right"])
    # +90 deg forward pedalling takes the front (right) pedal straight down
    apply_pose(arm, 90, 0)
    kp = posed_keypoints(arm)
    cl = s["crank_length_m"]
    assert kp["pedal_right"][1] == pytest.approx(kp0["crank_axle"][1] - cl, abs=1e-5)
    assert kp["pedal_right"][0] == pytest.approx(0.0, abs=1e-5)
    assert kp["pedal_left"][1] == pytest.approx(kp0["crank_axle"][1] + cl, abs=1e-5)
    assert kp["pedal_right"][2] == pytest.approx(kp0["pedal_right"][2], abs=1e-6)  # float32 bones
    with pytest.raises(ValueError):
        apply_pose(arm, float("nan"), 0)


def test_pose_after_save_and_reopen(fresh_scene, tmp_path):
    """Bone parenting survives bike.blend: a reopened bike poses like the freshly built one."""
    import bpy
    from addon.core.rig.articulation import apply_pose, posed_keypoints
    from addon.core.bike_asset import open_bike, save_bike
    from addon.core.procedural.build import build_bike

    s = specs.sample_spec("bmx", 0, 0)
    res = build_bike(s)
    rest = {n: world_vertices(o) for n, o in res["parts"].items()}
    save_bike(tmp_path / "bmx_00", s, res["keypoints"], layout.part_keypoints(s), {})
    bpy.ops.wm.read_factory_settings(use_empty=True)
    b = open_bike(tmp_path / "bmx_00")
    apply_pose(b["armature"], -60, 20, (0, 45, 0), (0, 0.2, 0))
    f = expected(b["keypoints"], None, -60, 20, (0, 45, 0), (0, 0.2, 0))
    for name, obj in b["parts"].items():
        assert np.abs(world_vertices(obj) - f(rest[name], name)).max() <= TOL, name
    got = posed_keypoints(b["armature"])
    assert np.abs(np.array(got["pedal_left"]) - f(b["keypoints"]["pedal_left"], "crank")).max() <= TOL

"""The 8-DoF bike pose against hand-written reference math (pure Python Rodrigues / Euler /
quaternions, independent of bike_pose.py and roma), on a synthetic bike folder."""
import math
import os
import random

import pytest
import torch

from splatting.bike.model import BikeModel
from splatting.bike.pose import check_poses, parse_pose_string, poses_from_json, transform_gaussians
from cyclist_formats.errors import UserError
from splatting.gaussians.container import read_ply
from splatting.gaussians.sh import sh_basis

from helpers import (ANCHORS, KP, KP_PARTS, make_bike, mat_mul, mat_vec, quat_to_R,  # noqa: F401
                     random_pose, ref_global, ref_global_R, ref_part_point, ref_part_R, rodrigues, rotate_about,
                     steer_axis)

@pytest.fixture(scope="module")
def bike_dir(tmp_path_factory):
    return make_bike(tmp_path_factory.mktemp("bikes"))


@pytest.fixture(scope="module")
def model(bike_dir):
    return BikeModel.load(bike_dir)


def close(a, b, tol=1e-5):
    return max(abs(float(x) - float(y)) for x, y in zip(a, b)) < tol


# ------------------------------------------------------------- signs and formulas

def test_positive_steering_turns_front_wheel_left(model):
    kp = model.pose([0, 30, 0, 0, 0, 0, 0, 0]).keypoints
    assert kp["front_axle"][2] < -0.02  # towards -Z: the rider's left (axle sits ahead of the axis)
    # the front of the front wheel, with the model's own transform, swings left too
    H = model.part_transforms([0, 30, 0, 0, 0, 0, 0, 0])["steering"][0]
    tip = H[:3, :3] @ torch.tensor([0.95, 0.35, 0.0], dtype=torch.float64) + H[:3, 3]
    assert tip[2] < -0.1
    assert close(kp["front_axle"], rotate_about(KP["front_axle"], KP["steer_bottom"], steer_axis(), math.radians(30)))
    assert close(kp["rear_axle"], KP["rear_axle"]) and close(kp["steer_top"], KP["steer_top"])


def test_positive_pedal_angle_takes_front_pedal_down(model):
    kp = model.pose([90, 0, 0, 0, 0, 0, 0, 0]).keypoints
    # pedal_right is the front pedal (+X); a quarter turn forward puts it straight below the axle
    assert close(kp["pedal_right"], [0.0, 0.30 - 0.17, 0.12])
    assert close(kp["pedal_left"], [0.0, 0.30 + 0.17, -0.12])
    assert close(kp["front_axle"], KP["front_axle"])


def test_global_rotation_order_is_x_then_y_then_z(model):
    pose = [0, 0, 20, 35, -50, 0.5, 0.2, -1.0]
    got = model.pose(pose).keypoints["seat"]
    assert close(got, ref_global(KP["seat"], pose))
    # the reverse order (z first) lands elsewhere, so the test can tell them apart
    ax, ay, az = (math.radians(a) for a in pose[2:5])
    rev = KP["seat"]
    for axis, ang in (([0, 0, 1], az), ([0, 1, 0], ay), ([1, 0, 0], ax)):
        rev = mat_vec(rodrigues(axis, ang), rev)
    assert not close(got, [a + t for a, t in zip(rev, pose[5:8])], 1e-2)


def test_keypoints_match_reference_for_random_poses(model):
    rng = random.Random(1)
    poses = [random_pose(rng) for _ in range(10)]
    out = model.pose(poses)
    part_of = {k: p for p, ks in KP_PARTS.items() for k in ks}
    for pose, posed in zip(poses, out):
        for name, xyz in KP.items():
            assert close(posed.keypoints[name], ref_part_point(part_of[name], xyz, pose)), (name, pose)


def test_gaussians_move_with_their_part(model, bike_dir):
    rng = random.Random(2)
    pose = random_pose(rng)
    posed = model.pose(pose)
    g = posed.gaussians
    for part, (a, e) in zip(model.part_names, model.ranges):
        canon = read_ply(os.path.join(bike_dir, "gaussians", part + ".ply"))
        # the first Gaussian of each part sits on a keypoint and must land on the posed keypoint
        assert close(g.means[a], posed.keypoints[ANCHORS[part][0]], 1e-5)
        for j in (a + 1, a + 5, e - 1):
            c = j - a
            assert close(g.means[j], ref_part_point(part, canon.means[c].tolist(), pose), 1e-5)
            Rp = ref_part_R(part, pose)
            want = mat_mul(Rp, quat_to_R(canon.quats[c]))
            got = quat_to_R(g.quats[j])
            assert max(abs(want[r][s] - got[r][s]) for r in range(3) for s in range(3)) < 1e-5
            # colour seen along R d after posing == colour seen along d before
            d = torch.nn.functional.normalize(torch.randn(5, 3), dim=-1)
            Rt = torch.tensor(Rp, dtype=torch.float32)
            before = torch.einsum("dk,kc->dc", sh_basis(d, 3), canon.sh[c])
            after = torch.einsum("dk,kc->dc", sh_basis(d @ Rt.T, 3), g.sh[j])
            assert torch.allclose(before, after, atol=1e-5)
    assert torch.equal(g.log_scales, model.canonical.log_scales)
    assert torch.equal(g.opacity_logits, model.canonical.opacity_logits)


def test_composition_order_is_frame_steering_crank(model, bike_dir):
    sizes = [len(read_ply(os.path.join(bike_dir, "gaussians", p + ".ply"))) for p in ("frame", "steering", "crank")]
    assert model.part_names == ["frame", "steering", "crank"]
    assert [e - a for a, e in model.ranges] == sizes
    g = model.pose([0] * 8).gaussians
    assert len(g) == sum(sizes)
    assert torch.allclose(g.means, model.canonical.means, atol=1e-6)


def test_batch_equals_loop(model):
    rng = random.Random(3)
    poses = [random_pose(rng) for _ in range(5)]
    batch = model.pose(poses)
    for pose, b in zip(poses, batch):
        one = model.pose(pose)
        for f in ("means", "quats", "sh", "log_scales", "opacity_logits"):
            assert torch.allclose(getattr(b.gaussians, f), getattr(one.gaussians, f), atol=1e-6), f
        for k in KP:
            assert torch.allclose(b.keypoints[k], one.keypoints[k])
    t = model.pose_tensors(poses)
    assert t["means"].shape == (5, len(model), 3) and t["sh"].shape == (5, len(model), 16, 3)
    assert t["keypoints"].shape == (5, len(KP), 3)


def test_reference_transform_gaussians_agrees(model):
    pose = [0, 0, 10, 20, 30, 1, 2, 3]
    H = model.part_transforms(pose)["frame"][0]
    a, e = model.ranges[0]
    ref = transform_gaussians(model.canonical[a:e], H)
    got = model.pose(pose).gaussians[a:e]
    assert torch.allclose(ref.means, got.means, atol=1e-5)
    assert torch.allclose(ref.quats, got.quats, atol=1e-5)
    assert torch.allclose(ref.sh, got.sh, atol=1e-5)


def test_sh_degree_zero_bike(tmp_path):
    m = BikeModel.load(make_bike(tmp_path, sh_degree=0))
    assert m.sh_degree == 0
    g = m.pose([10, 10, 10, 10, 10, 0, 0, 0]).gaussians
    assert torch.equal(g.sh, m.canonical.sh)


def test_crankless_rideable_ignores_theta_p(tmp_path):
    m = BikeModel.load(make_bike(tmp_path, "scooter", crank=False))
    assert not m.has_crank and m.part_names == ["frame", "steering"]
    a = m.pose([0, 20, 5, 6, 7, 1, 0, 0])
    b = m.pose([123, 20, 5, 6, 7, 1, 0, 0])
    assert torch.equal(a.gaussians.means, b.gaussians.means)
    assert all(torch.equal(a.keypoints[k], b.keypoints[k]) for k in a.keypoints)
    assert "crank_axle" not in a.keypoints
    steer = m.pose([0, 20, 0, 0, 0, 0, 0, 0]).keypoints
    assert close(steer["front_axle"], rotate_about(KP["front_axle"], KP["steer_bottom"], steer_axis(), math.radians(20)))


# ------------------------------------------------------------- optional sub-parts

def test_wheel_and_pedal_sub_parts(tmp_path):
    d = make_bike(tmp_path, sub_parts=("front_wheel", "rear_wheel", "pedal_left", "pedal_right"),
                  meta_extra={"gear_ratio": 2.5})
    m = BikeModel.load(d)
    assert m.part_names == ["frame", "steering", "crank", "front_wheel", "rear_wheel", "pedal_left", "pedal_right"]
    theta = 10.0
    posed = m.pose([theta, 0, 0, 0, 0, 0, 0, 0]).gaussians
    rw = m.part_names.index("rear_wheel")
    a, e = m.ranges[rw]
    canon = read_ply(os.path.join(d, "gaussians", "rear_wheel.ply"))
    want = rotate_about(canon.means[3].tolist(), KP["rear_axle"], [0, 0, 1], -math.radians(theta * 2.5))
    assert close(posed.means[a + 3], want)
    # a point above the axle moves forward when pedalling forward (the wheel rolls forward)
    top = torch.tensor([KP["rear_axle"][0], KP["rear_axle"][1] + 0.3, 0.0])
    R = torch.tensor(rodrigues([0, 0, 1], -math.radians(theta * 2.5)), dtype=torch.float32)
    assert (R @ (top - torch.tensor(KP["rear_axle"])))[0] > 0
    # the front wheel spins about its axle, then steers with the fork
    fw = m.part_names.index("front_wheel")
    a, e = m.ranges[fw]
    canon = read_ply(os.path.join(d, "gaussians", "front_wheel.ply"))
    both = m.pose([theta, 25, 0, 0, 0, 0, 0, 0]).gaussians
    spun = rotate_about(canon.means[4].tolist(), KP["front_axle"], [0, 0, 1], -math.radians(theta * 2.5))
    assert close(both.means[a + 4], rotate_about(spun, KP["steer_bottom"], steer_axis(), math.radians(25)))
    # pedals stay level: orientation unchanged, position follows the pedal keypoint
    pr = m.part_names.index("pedal_right")
    a, e = m.ranges[pr]
    p90 = m.pose([90, 0, 0, 0, 0, 0, 0, 0])
    assert torch.allclose(p90.gaussians.quats[a:e], m.canonical.quats[a:e], atol=1e-6)
    assert close(p90.gaussians.means[a], p90.keypoints["pedal_right"])


def test_wheel_sub_parts_need_gear_ratio(tmp_path):
    d = make_bike(tmp_path, sub_parts=("front_wheel",))
    with pytest.raises(UserError, match="gear_ratio"):
        BikeModel.load(d)


# ------------------------------------------------------------- invalid input

@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_non_finite_pose_rejected(model, bad):
    with pytest.raises(UserError, match="finite"):
        model.pose([0, 0, 0, 0, bad, 0, 0, 0])
    with pytest.raises(UserError, match="theta_s_deg"):
        check_poses([[0] * 8, [0, bad, 0, 0, 0, 0, 0, 0]])


def test_pose_shape_and_text_rejected(model):
    with pytest.raises(UserError, match="8 values"):
        model.pose([0, 0, 0])
    with pytest.raises(UserError):
        model.pose("abc")
    with pytest.raises(UserError, match="8 comma-separated"):
        parse_pose_string("1,2,3")
    with pytest.raises(UserError, match="theta_x_deg"):
        parse_pose_string("1,2,x,4,5,6,7,8")
    with pytest.raises(UserError, match="finite"):
        parse_pose_string("1,2,3,4,5,6,7,nan")
    assert parse_pose_string("1, 2,3,4,5,6,7,-8.5").tolist() == [1, 2, 3, 4, 5, 6, 7, -8.5]


def test_poses_json_forms():
    names = ["theta_p_deg", "theta_s_deg", "theta_x_deg", "theta_y_deg", "theta_z_deg", "t_x_m", "t_y_m", "t_z_m"]
    d = dict(zip(names, range(8)))
    assert poses_from_json([d, list(range(8))]).tolist() == [list(range(8))] * 2
    with pytest.raises(UserError, match="missing"):
        poses_from_json([{k: v for k, v in d.items() if k != "t_z_m"}])
    with pytest.raises(UserError, match="unknown"):
        poses_from_json([dict(d, theta_q_deg=1)])
    with pytest.raises(UserError, match="non-empty"):
        poses_from_json([])
    with pytest.raises(UserError, match="numbers"):
        poses_from_json([[0, 0, 0, 0, 0, 0, 0, "x"]])


def test_coincident_steering_keypoints(tmp_path):
    kp = dict(KP, steer_top=list(KP["steer_bottom"]))
    with pytest.raises(UserError, match="coincide"):
        BikeModel.load(make_bike(tmp_path, kp=kp))


def test_missing_part_file(tmp_path):
    d = make_bike(tmp_path)
    os.remove(os.path.join(d, "gaussians", "steering.ply"))
    with pytest.raises(UserError, match="steering.ply"):
        BikeModel.load(d)
    d2 = make_bike(tmp_path, "b2")
    os.remove(os.path.join(d2, "gaussians", "crank.ply"))
    with pytest.raises(UserError, match="crank.ply"):
        BikeModel.load(d2)


def test_bike_id_mismatch(tmp_path):
    d = make_bike(tmp_path, "road_07")
    assert BikeModel.load(d, bike_id="road_07").bike_id == "road_07"
    with pytest.raises(UserError, match="does not match"):
        BikeModel.load(d, bike_id="road_08")


def test_missing_keypoints_and_files(tmp_path):
    kp = {k: v for k, v in KP.items() if k != "front_axle"}
    with pytest.raises(UserError, match="front_axle"):
        BikeModel.load(make_bike(tmp_path, kp=kp))
    d = make_bike(tmp_path, "b3")
    os.remove(os.path.join(d, "meta.json"))
    with pytest.raises(UserError, match="meta.json"):
        BikeModel.load(d)
    with pytest.raises(UserError, match="no bike folder"):
        BikeModel.load(os.path.join(str(tmp_path), "nope"))
    d4 = make_bike(tmp_path, "b4")
    with open(os.path.join(d4, "keypoints.json"), "w") as f:
        f.write("{not json")
    with pytest.raises(UserError, match="not valid JSON"):
        BikeModel.load(d4)
    kp = dict(KP, seat=[0.0, float("nan"), 0.0])
    with pytest.raises(UserError, match="seat"):
        BikeModel.load(make_bike(tmp_path, "b5", kp=kp))


def test_reuse_overwrites_buffers_with_the_same_result(model):
    rng = random.Random(4)
    a = [random_pose(rng) for _ in range(3)]
    b = [random_pose(rng) for _ in range(3)]
    first = model.pose_tensors(a)
    fresh_b = model.pose_tensors(b)
    reused = model.pose_tensors(b, reuse=first)
    assert reused["means"].data_ptr() == first["means"].data_ptr()
    for f in ("means", "quats", "sh", "keypoints"):
        assert torch.allclose(reused[f], fresh_b[f], atol=1e-6), f
    with pytest.raises(ValueError):
        model.pose_tensors(b[:2], reuse=first)


def test_generic_pose_transforms_match_the_model(model):
    from splatting.bike.pose import pose_transforms

    pose = [40, -25, 10, -70, 5, 0.3, 0.0, 2.0]
    H = pose_transforms(pose, KP["steer_bottom"], KP["steer_top"], KP["crank_axle"])
    parts = model.part_transforms(pose)
    assert torch.allclose(H["global"] @ H["steer"], parts["steering"], atol=1e-12)
    assert torch.allclose(H["global"] @ H["pedal"], parts["crank"], atol=1e-12)
    assert torch.allclose(H["global"], parts["frame"], atol=1e-12)
    R = H["global"][0, :3, :3].tolist()
    want = ref_global_R(pose)
    assert max(abs(R[i][j] - want[i][j]) for i in range(3) for j in range(3)) < 1e-12


def test_global_pose_with_camera_keeps_the_render(model):
    """Posing by H_g alone and moving the camera by H_g too must leave the image unchanged
    (means, quaternions and SH all follow), also when fed the model's strided output views."""
    rast = pytest.importorskip("splatting.raster.sparse")
    from splatting.raster.camera import Camera

    W = H = 40
    K = torch.tensor([[45.0, 0, W / 2], [0, 45.0, H / 2], [0, 0, 1]])
    cam = Camera(torch.tensor([[-1.0, 0, 0], [0, -1, 0], [0, 0, 1]]), torch.tensor([0.0, 0.6, 3.0]), K, W, H)
    pose = [0, 0, 12, 100, -8, 0.4, 0.1, -0.7]
    Hg = model.part_transforms(pose)["frame"][0].float()
    R, t = Hg[:3, :3], Hg[:3, 3]
    moved_cam = Camera(cam.R @ R.T, cam.T - cam.R @ R.T @ t, K, W, H)
    posed = model.pose(pose).gaussians
    assert not posed.means.is_contiguous()  # the strided views reach the rasterizer as they are
    before = rast.render_gaussians(model.canonical, cam)["rgb"]
    after = rast.render_gaussians(posed, moved_cam)["rgb"]
    assert before.std() > 0.02
    assert (before - after).abs().max() < 2e-3


def _write_metrics(d, part, antialiased):
    import json
    with open(os.path.join(d, "gaussians", part + ".json"), "w") as f:
        json.dump({"psnr": 30.0, "config": {"antialiased": antialiased}}, f)


def test_antialiased_flag_comes_from_the_parts_training(tmp_path):
    # no metrics (imported parts): plain splatting
    assert BikeModel.load(make_bike(tmp_path, "plain")).antialiased is False
    d = make_bike(tmp_path, "aa")
    for p in ("frame", "steering", "crank"):
        _write_metrics(d, p, True)
    assert BikeModel.load(d).antialiased is True
    d = make_bike(tmp_path, "off")
    for p in ("frame", "steering", "crank"):
        _write_metrics(d, p, False)
    assert BikeModel.load(d).antialiased is False


def test_a_library_fine_tuned_bike_takes_the_flag_from_its_rest_trained_parts(tmp_path):
    """The library's posed stage: <part>.ply fine-tuned, the training metrics in <part>_rest.json
    (no <part>.json); load(suffix="_rest") reads the rest-trained parts themselves."""
    import shutil
    d = make_bike(tmp_path, "lib")
    g = os.path.join(d, "gaussians")
    for p in ("frame", "steering", "crank"):
        _write_metrics(d, p, True)
        os.rename(os.path.join(g, p + ".json"), os.path.join(g, p + "_rest.json"))
        shutil.copyfile(os.path.join(g, p + ".ply"), os.path.join(g, p + "_rest.ply"))
    assert BikeModel.load(d).antialiased is True
    assert BikeModel.load(d, suffix="_rest").antialiased is True
    os.remove(os.path.join(g, "crank_rest.ply"))
    with pytest.raises(UserError, match="crank_rest.ply"):
        BikeModel.load(d, suffix="_rest")


def test_parts_trained_with_and_without_antialiasing_are_refused(tmp_path):
    d = make_bike(tmp_path, "mixed")
    _write_metrics(d, "frame", True)
    _write_metrics(d, "steering", False)  # crank has none: plain
    with pytest.raises(UserError, match="with and without antialiasing"):
        BikeModel.load(d)

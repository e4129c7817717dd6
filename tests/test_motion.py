"""Motion inputs (CLIFF, AMASS), the built-in pedalling motion and theta_p/theta_s recovery."""
import math

import numpy as np
import pytest
import torch

from cyclist_formats.errors import UserError
from splatting.rider.kinematics import JOINT_INDEX, forward_kinematics
from splatting.rider.motion import (BikeFit, load_amass, load_cliff, load_motion, pedal_pose,
                                    pedalling_motion, sweep_motion, theta_from_pose)

J = JOINT_INDEX


@pytest.fixture(scope="module")
def riders():
    torch.set_num_threads(1)
    from splatting.rider.roster import load_rider
    return [load_rider(i) for i in ("f_teen_slim_150", "m_adult_average_185", "m_senior_athletic_195")]


def _wrap_deg(x):
    return (torch.rad2deg(x) + 180) % 360 - 180


def _posed(rider, rot, root):
    return forward_kinematics(rider.joints.double(), rot, root)[0]


def test_theta_recovered_from_builtin_poses(riders):
    tp = torch.deg2rad(torch.arange(0.0, 360.0, 10.0))
    ts = torch.deg2rad(torch.linspace(-30.0, 30.0, len(tp)))
    fit = BikeFit()
    for rider in riders:
        rot, root, targets = pedal_pose(rider.joints, tp, ts, fit)
        j = _posed(rider, rot, root)
        # The pose really puts ankles and wrists on their goals (all reachable here).
        for name in ("left_ankle", "right_ankle", "left_wrist", "right_wrist"):
            assert (j[:, J[name]] - targets[name]).norm(dim=-1).max() < 1e-6, name
        p, s = theta_from_pose(j, steer_axis=fit.steer_axis)
        assert _wrap_deg(p - tp).abs().max() < 2.0
        assert _wrap_deg(s - ts).abs().max() < 2.0
        # The paper's plain X-Z projection shrinks theta_s by ~cos(18 deg): still within 2 deg
        # up to 30 deg of steering, and clearly biased (a real, measurable difference).
        _, s_paper = theta_from_pose(j)
        err = _wrap_deg(s_paper - ts).abs()
        assert err.max() < 2.0 and err.max() > 0.5


def test_theta_from_known_geometry():
    # Hand-built joints: ankles on a crank at 40 deg forward pedalling, wrists turned 15 deg left.
    j = torch.zeros(1, 24, 3, dtype=torch.float64)
    a = math.radians(40.0)
    j[0, J["right_ankle"]] = torch.tensor([0.17 * math.cos(a), -0.17 * math.sin(a), 0.1])
    j[0, J["left_ankle"]] = torch.tensor([-0.17 * math.cos(a), 0.17 * math.sin(a), -0.1])
    s = math.radians(15.0)
    j[0, J["right_wrist"]] = torch.tensor([0.6 + 0.2 * math.sin(s), 1.0, 0.2 * math.cos(s)])
    j[0, J["left_wrist"]] = torch.tensor([0.6 - 0.2 * math.sin(s), 1.0, -0.2 * math.cos(s)])
    p, st = theta_from_pose(j)
    assert abs(math.degrees(p.item()) - 40.0) < 1e-4
    assert abs(math.degrees(st.item()) - 15.0) < 1e-4
    j[0, 3, 0] = float("nan")
    with pytest.raises(UserError):
        theta_from_pose(j)


def test_pedalling_posture(riders):
    rider = riders[1]
    m = pedalling_motion(rider, n_frames=12)
    root = m.root_trans(rider)
    j = _posed(rider, m.local_rotmats, root)
    assert torch.allclose(j[:, 0], torch.zeros(12, 3, dtype=torch.float64), atol=1e-9)  # pelvis at origin
    # Knees bend forward (ahead of the hip-ankle line), elbows stay bent, hands ahead and below the shoulders.
    for s in ("left", "right"):
        hip, knee, ankle = j[:, J[f"{s}_hip"]], j[:, J[f"{s}_knee"]], j[:, J[f"{s}_ankle"]]
        d = ankle - hip
        n = torch.stack([-d[:, 1], d[:, 0]], -1)  # in-plane normal pointing forward-up
        assert (((knee - hip)[:, :2] * n).sum(-1) > 0).all()
        assert (j[:, J[f"{s}_wrist"], 0] > j[:, J[f"{s}_shoulder"], 0] + 0.2).all()
        assert (j[:, J[f"{s}_wrist"], 1] < j[:, J[f"{s}_shoulder"], 1]).all()
    # Antiphase: the left ankle is the right one mirrored through the crank centre.
    centre = 0.5 * (j[:, J["left_ankle"], :2] + j[:, J["right_ankle"], :2])
    assert (centre - centre[0]).norm(dim=-1).max() < 1e-6
    assert (j[:, J["left_ankle"], 1] - j[:, J["right_ankle"], 1]).abs().max() > 0.3


def test_sweep_grid(riders):
    m = sweep_motion(riders[0], theta_p_deg=(0, 360, 90), theta_s_deg=(-20, 20, 20))
    assert len(m) == 4 * 3
    j = _posed(riders[0], m.local_rotmats, m.root_trans(riders[0]))
    p, s = theta_from_pose(j, steer_axis=BikeFit().steer_axis)
    assert _wrap_deg(p - m.theta_p).abs().max() < 2.0 and _wrap_deg(s - m.theta_s).abs().max() < 2.0
    with pytest.raises(UserError):
        sweep_motion(riders[0], theta_s_deg=(10, -10, 5))


def _save(path, **arrays):
    np.savez(path, **arrays)
    return path


def test_amass_z_up_puts_head_up(riders, tmp_path):
    rider = riders[1]
    n = 3
    poses = np.zeros((n, 156))
    poses[:, :3] = [math.pi / 2, 0.0, 0.0]  # AMASS standing subject: SMPL Y-up body turned into Z-up
    poses[:, 4 * 3:4 * 3 + 3] = [1.0, 0.0, 0.0]  # SMPL left knee flexion (+X in SMPL's frame)
    trans = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 2.0, 1.0]])
    m = load_motion(_save(tmp_path / "a.npz", poses=poses, trans=trans, mocap_framerate=120.0))
    assert m.fps == 120.0
    np.testing.assert_allclose(m.pelvis[:, 1].numpy(), 1.0)  # Z-up height -> Y
    j = _posed(rider, m.local_rotmats, m.root_trans(rider))
    assert (j[:, J["head"], 1] - j[:, J["pelvis"], 1] > 0.4).all()
    # Facing +X: toes ahead of the heels; knee flexion sends the left shin backward (-X).
    assert (j[:, J["right_foot"], 0] > j[:, J["right_ankle"], 0]).all()
    assert (j[:, J["left_ankle"], 0] < j[:, J["left_knee"], 0] - 0.2).all()
    assert (j[:, J["left_hip"], 2] < 0).all()


def test_cliff_formats_agree(tmp_path):
    n = 2
    rng = np.random.default_rng(0)
    aa = rng.normal(scale=0.3, size=(n, 24, 3))
    aa[:, 0] = [math.pi, 0.0, 0.0]  # upright person seen by an OpenCV camera (y down)
    t = np.array([[0.1, 0.2, 5.0], [0.0, 0.0, 4.0]])
    m1 = load_cliff(_save(tmp_path / "c1.npz", pose=aa.reshape(n, 72), shape=np.zeros((n, 10)), global_t=t))
    from splatting.rotations import axis_angle_to_rotmat
    R = axis_angle_to_rotmat(torch.from_numpy(aa)).numpy()
    m2 = load_motion(_save(tmp_path / "c2.npz", pose=R, shape=np.zeros((n, 10)), global_t=t))
    np.testing.assert_allclose(m1.local_rotmats.numpy(), m2.local_rotmats.numpy(), atol=1e-9)
    # Root Rx(pi) in the camera frame is an upright body in ours (identity root).
    aa[:, 1:] = 0
    m3 = load_cliff(_save(tmp_path / "c3.npz", pose=aa.reshape(n, 72), global_t=t))
    np.testing.assert_allclose(m3.local_rotmats[:, 0].numpy(), np.eye(3)[None].repeat(n, 0), atol=1e-9)
    assert m3.pelvis[0, 1] < 0  # camera y down (+0.2) is below in a Y-up world
    assert m1.betas.shape == (n, 10)


@pytest.mark.parametrize("arrays, match", [
    (dict(pose=np.zeros((2, 69)), global_t=np.zeros((2, 3))), "pose"),
    (dict(pose=np.zeros((2, 72))), "global_t"),
    (dict(pose=np.zeros((2, 72)), global_t=np.zeros((3, 3))), "global_t"),
    (dict(pose=np.full((2, 72), np.nan), global_t=np.zeros((2, 3))), "NaN"),
    (dict(pose=np.zeros((2, 24, 3, 3)), global_t=np.zeros((2, 3))), "det"),
])
def test_cliff_rejects(tmp_path, arrays, match):
    with pytest.raises(UserError, match=match):
        load_cliff(_save(tmp_path / "bad.npz", **arrays))


@pytest.mark.parametrize("arrays, match", [
    (dict(poses=np.zeros((2, 72)), trans=np.zeros((2, 3))), r"\(N,156\)"),
    (dict(poses=np.zeros((2, 156))), "trans"),
    (dict(poses=np.zeros((2, 156)), trans=np.zeros((2, 2))), "trans"),
    (dict(poses=np.zeros((2, 156)), trans=np.array([[0, 0, np.inf]] * 2)), "NaN"),
])
def test_amass_rejects(tmp_path, arrays, match):
    with pytest.raises(UserError, match=match):
        load_amass(_save(tmp_path / "bad.npz", **arrays))


def test_load_motion_rejects(tmp_path):
    with pytest.raises(UserError, match="not found"):
        load_motion(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(UserError, match="cannot read"):
        load_motion(tmp_path / "junk.npz")
    with pytest.raises(UserError, match="neither"):
        load_motion(_save(tmp_path / "other.npz", x=np.zeros(3)))

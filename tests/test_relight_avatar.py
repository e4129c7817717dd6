"""The relightable avatar: normals follow the skinning rotation that turns each Gaussian."""
import math

import numpy as np
import pytest
import torch

from cyclist_formats import bike_folder
from splatting.gaussians.container import Gaussians
from splatting.relight.avatar import RelightableAvatar
from splatting.rider.avatar import RiderAvatar
from splatting.rotations import quat_to_rotmat

RIDER_ID = "f_teen_slim_150"


@pytest.fixture(scope="module")
def avatar():
    torch.set_num_threads(1)
    from splatting.rider.roster import load_rider

    rider = load_rider(RIDER_ID)
    rng = np.random.default_rng(0)
    V = rider.vertices.double().numpy()
    pts = V[rng.choice(len(V), 200, replace=False)] + rng.normal(0, 0.003, (200, 3))
    g = torch.Generator().manual_seed(0)
    gs = Gaussians(torch.from_numpy(pts).float(), torch.randn(200, 4, generator=g),
                   torch.full((200, 3), -4.0), torch.full((200,), 2.0), torch.rand(200, 1, 3, generator=g))
    return RiderAvatar.from_rider(gs, rider), rider


def test_normals_turn_like_the_gaussians_axes(avatar, tmp_path):
    av, rider = avatar
    # each Gaussian's normal: its own first local axis.  Posing turns the Gaussian by quaternion
    # (quat' = q_R q); the normal is turned by the rotation matrix: both must agree
    R0 = quat_to_rotmat(av.gaussians.quats / av.gaussians.quats.norm(dim=-1, keepdim=True))
    normals = R0[:, :, 0].contiguous()
    ra = RelightableAvatar(av, torch.rand(len(av), 3), normals, torch.rand(len(av), 3) * 0.05)
    from splatting.rider.motion import pedal_pose

    rot, root, _ = pedal_pose(rider.joints, torch.tensor([math.radians(70.0), math.radians(250.0)]),
                              torch.tensor([0.2, -0.3]))
    posed = ra.pose(rot.float(), root.float())
    assert len(posed) == 2
    moved = 0.0
    for g, alb, n, gl in posed:
        q = g.quats / g.quats.norm(dim=-1, keepdim=True)
        axis = quat_to_rotmat(q)[:, :, 0]
        np.testing.assert_allclose(n.numpy(), axis.numpy(), atol=2e-5)
        assert torch.allclose(n.norm(dim=-1), torch.ones(len(n)), atol=1e-5)
        moved = max(moved, float((n - normals).norm(dim=-1).max()))
        assert alb is ra.albedo and gl is ra.gloss
    assert moved > 0.5  # the pedalling poses bend the legs: some normals turned a lot


def test_load_reads_the_relight_file_beside_rider_ply(avatar, tmp_path):
    av, _ = avatar
    folder = tmp_path / "av"
    av.save(folder)
    with pytest.raises(bike_folder.UserError, match="relight"):
        RelightableAvatar.load(folder)
    n = len(av)
    alb = np.random.default_rng(1).uniform(0, 1, (n, 3))
    bike_folder.write_relight(folder / "rider.ply", alb, np.tile([0.0, 1.0, 0.0], (n, 1)), np.zeros((n, 3)))
    ra = RelightableAvatar.load(folder)
    np.testing.assert_allclose(ra.albedo.numpy(), alb, rtol=1e-6)
    with pytest.raises(ValueError):
        RelightableAvatar(av, ra.albedo[:-1], ra.normals, ra.gloss)
    # view-dependent normals (a bike's) are refused, not silently dropped
    bike_folder.write_relight(folder / "rider.ply", alb, np.tile([0.0, 1.0, 0.0], (n, 1)), np.zeros((n, 3)),
                              np.zeros((n, 3, 3)))
    with pytest.raises(bike_folder.UserError, match="view-dependent"):
        RelightableAvatar.load(folder)

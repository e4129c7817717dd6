"""Rider Gaussian avatar: LBS of means, rotations and SH; skinning weights; avatar files; the
Blender import of a rider mesh.

Synthetic avatars: a few hundred Gaussians sampled on the rider's rest mesh with its vertex
colours (no trained model, no Blender training needed)."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from splatting.raster.camera import ring_camera
from cyclist_formats.errors import UserError
from splatting.gaussians.container import Gaussians
from splatting.raster.sparse import render_gaussians
from splatting.rider.avatar import RiderAvatar, nearest_surface_point, polar_rotation, quat_mul, rotmat_to_quat_wxyz
from splatting.rider.kinematics import JOINT_INDEX

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RIDER_ID = "f_teen_slim_150"


@pytest.fixture(scope="module")
def rider():
    torch.set_num_threads(1)
    from splatting.rider.roster import load_rider
    return load_rider(RIDER_ID)


def _sample_surface(rider, n, seed):
    """Area-uniform points on the rest mesh: positions, their triangle and barycentric coords."""
    rng = np.random.default_rng(seed)
    V, F = rider.vertices.double().numpy(), rider.faces.numpy()
    tris = V[F]
    area = np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1)
    fi = rng.choice(len(F), n, p=area / area.sum())
    b = rng.dirichlet(np.ones(3), n)
    return (b[:, :, None] * tris[fi]).sum(1), fi, b


def synthetic_gaussians(rider, n=300, sh_degree=2, seed=0):
    pts, fi, b = _sample_surface(rider, n, seed)
    g = torch.Generator().manual_seed(seed)
    col = (torch.from_numpy(b)[:, :, None] * rider.colors.double()[rider.faces[fi]]).sum(1).float()
    k = (sh_degree + 1) ** 2
    sh = 0.3 * torch.randn(n, k, 3, generator=g)  # view-dependent lobes: the SH rotation matters
    sh[:, 0] = (col - 0.5) / 0.28209479177387814
    return Gaussians(torch.from_numpy(pts).float(), torch.randn(n, 4, generator=g),
                     torch.log(torch.rand(n, 3, generator=g) * 0.02 + 0.005), torch.full((n,), 2.0), sh)


@pytest.fixture(scope="module")
def avatar(rider):
    return RiderAvatar.from_rider(synthetic_gaussians(rider), rider)


def _random_rotations(n, max_deg, seed):
    import roma
    g = torch.Generator().manual_seed(seed)
    aa = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=torch.float64), dim=-1)
    return roma.rotvec_to_rotmat(aa * torch.rand(n, 1, generator=g, dtype=torch.float64) * math.radians(max_deg))


def _quat_close(a, b, tol):
    a = torch.nn.functional.normalize(a, dim=-1)
    b = torch.nn.functional.normalize(b, dim=-1)
    return float((1 - (a * b).sum(-1).abs()).max()) < tol  # q and -q are the same rotation


def test_identity_pose_returns_rest(avatar):
    eye = torch.eye(3, dtype=torch.float64).repeat(1, 24, 1, 1)
    posed = avatar.pose(eye, torch.zeros(1, 3, dtype=torch.float64))
    g = avatar.gaussians
    assert torch.allclose(posed.means, g.means, atol=1e-6)
    assert _quat_close(posed.quats, g.quats, 1e-6)
    assert torch.allclose(posed.sh, g.sh, atol=1e-5)
    assert torch.equal(posed.log_scales, g.log_scales) and torch.equal(posed.opacity_logits, g.opacity_logits)


def test_rigid_root_motion_moves_everything_rigidly(avatar, rider):
    R = _random_rotations(1, 170, seed=3)[0]
    t = torch.tensor([0.3, -0.2, 0.5], dtype=torch.float64)
    rot = torch.eye(3, dtype=torch.float64).repeat(1, 24, 1, 1)
    rot[0, 0] = R
    posed = avatar.pose(rot, t[None])
    pelvis = rider.joints[0].double()
    g = avatar.gaussians
    expect = (g.means.double() - pelvis) @ R.T + pelvis + t
    assert torch.allclose(posed.means.double(), expect, atol=1e-5)
    qR = rotmat_to_quat_wxyz(R.float())
    assert _quat_close(posed.quats, quat_mul(qR.expand(len(g), 4), g.quats), 1e-6)

    # Moving the avatar and the camera together leaves the image unchanged: a wrong SH or
    # quaternion rotation would change colours / splat shapes.
    cam = ring_camera(40.0, orbit_centre=(0.0, 0.8, 0.0), size=96, focal=2084.97 * 96 / 512)
    c = pelvis + t - R @ pelvis  # x' = R x + c
    Rc = cam.R.double() @ R.T
    cam2 = type(cam)(Rc.float(), (cam.T.double() - Rc @ c).float(), cam.K, cam.width, cam.height)
    with torch.no_grad():
        a = render_gaussians(g, cam)
        b = render_gaussians(posed, cam2)
    assert a["alpha"].sum() > 50  # the avatar is in view
    assert float((a["rgb"] - b["rgb"]).abs().max()) < 2e-3
    assert float((a["alpha"] - b["alpha"]).abs().max()) < 2e-3


def test_posed_means_follow_the_mesh(rider):
    from splatting.rider.body import pose_vertices
    from splatting.rider.motion import pedal_pose

    pts, fi, b = _sample_surface(rider, 400, seed=1)
    # Gaussians on the surface plus some exactly on vertices
    vid = torch.arange(0, len(rider.vertices), 97)
    means = torch.cat([torch.from_numpy(pts).float(), rider.vertices[vid]])
    n = len(means)
    g = Gaussians(means, torch.tensor([1.0, 0, 0, 0]).repeat(n, 1), torch.full((n, 3), -5.0),
                  torch.zeros(n), torch.zeros(n, 1, 3))
    av = RiderAvatar.from_rider(g, rider)
    theta = torch.tensor([0.0, 1.3, 2.9, 4.4])
    rot, root, _ = pedal_pose(rider.joints, theta, theta / 10)
    yaw = torch.tensor([[math.cos(1.0), 0, math.sin(1.0)], [0, 1, 0], [-math.sin(1.0), 0, math.cos(1.0)]],
                       dtype=torch.float64)
    rot[:, 0] = yaw @ rot[:, 0]
    out = av.pose_tensors(rot, root)["means"].double()
    pv = pose_vertices(rider, rot, root)  # (B, V, 3)
    # exactly on vertices: the same LBS
    assert float((out[:, 400:] - pv[:, vid]).norm(dim=-1).max()) < 1e-4
    # on triangles: the barycentric point of the posed triangle, within 1 cm (LBS is not affine
    # across a triangle, but nearly so at this mesh resolution)
    F = rider.faces[fi]
    tri_pts = (torch.from_numpy(b)[None, :, :, None] * pv[:, F]).sum(2)
    err = (out[:, :400] - tri_pts).norm(dim=-1)
    assert float(err.max()) < 0.01
    # and the posed Gaussians actually moved (the pose is far from the T-pose)
    assert float((out[:, :400] - means[:400].double()).norm(dim=-1).mean()) > 0.1


def test_skinning_weights_at_vertices_and_on_triangles(rider):
    V, F, W = rider.vertices.double(), rider.faces.numpy(), rider.weights.double()
    vid = np.arange(5, len(V), 501)
    fidx, bary = nearest_surface_point(V[vid], V, F)
    assert np.allclose(bary.max(1), 1.0, atol=1e-6)  # a vertex is a corner of its nearest triangle
    corner = rider.faces.numpy()[fidx, bary.argmax(1)]
    assert np.allclose(V.numpy()[corner], V.numpy()[vid])  # that corner (or a coincident vertex)
    pts, fi, b = _sample_surface(rider, 50, seed=4)
    # brute force: the closest point over all triangles
    import trimesh
    tris = V.numpy()[F]
    for i in range(0, 50, 10):
        cp = trimesh.triangles.closest_point(tris, np.repeat(pts[i:i + 1] + 0.002, len(tris), 0))
        d_all = np.linalg.norm(cp - (pts[i] + 0.002), axis=1).min()
        f1, b1 = nearest_surface_point(pts[i:i + 1] + 0.002, V, F)
        mine = (b1[0, :, None] * tris[f1[0]]).sum(0)
        assert abs(np.linalg.norm(mine - (pts[i] + 0.002)) - d_all) < 1e-9
    from splatting.rider.avatar import skinning_weights
    w = skinning_weights(torch.from_numpy(pts), V, F, W)
    assert torch.allclose(w.sum(1), torch.ones(50), atol=1e-5)
    assert torch.allclose(w.double(), (torch.from_numpy(b)[:, :, None] * W[torch.from_numpy(F[fi])]).sum(1), atol=1e-4)


def test_polar_rotation_matches_svd():
    import roma
    R1 = _random_rotations(500, 180, seed=5)
    R2 = R1 @ _random_rotations(500, 150, seed=6)
    w = torch.rand(500, 1, 1, dtype=torch.float64)
    M = (1 - w) * R1 + w * R2
    assert torch.allclose(polar_rotation(M), roma.special_procrustes(M), atol=1e-7)


def test_batched_pose_equals_single_poses(avatar, rider):
    from splatting.rider.motion import pedal_pose
    rot, root, _ = pedal_pose(rider.joints, torch.tensor([0.2, 2.0, 4.0]), torch.tensor([0.0, 0.3, -0.3]))
    batch = avatar.pose(rot, root)
    assert isinstance(batch, list) and len(batch) == 3
    for b in range(3):
        one = avatar.pose(rot[b], root[b])
        assert torch.allclose(one.means, batch[b].means) and torch.allclose(one.sh, batch[b].sh, atol=1e-6)
        # the SH follow the Gaussian's rotation (rotation-invariant band energies, changed coefficients)
        e = lambda s: s[:, 1:4].pow(2).sum(1)
        assert torch.allclose(e(one.sh), e(avatar.gaussians.sh), atol=1e-4)


def test_save_load_round_trip(avatar, tmp_path):
    avatar.save(tmp_path / "av")
    back = RiderAvatar.load(tmp_path / "av")
    assert back.rider_id == RIDER_ID
    assert torch.equal(back.weights, avatar.weights) and torch.equal(back.rest_joints, avatar.rest_joints)
    assert torch.equal(back.gaussians.means, avatar.gaussians.means)
    assert torch.allclose(back.gaussians.sh, avatar.gaussians.sh)
    rot = _random_rotations(24, 40, seed=7)[None]
    assert torch.allclose(back.pose(rot).means, avatar.pose(rot).means, atol=1e-6)


def test_missing_and_corrupt_avatars(avatar, tmp_path):
    with pytest.raises(UserError, match="missing .*rider.ply"):
        RiderAvatar.load(tmp_path / "nothing")
    d = tmp_path / "av"
    avatar.save(d)
    (d / "skinning.npz").write_bytes(b"not a zip file")
    with pytest.raises(UserError, match="cannot read"):
        RiderAvatar.load(d)
    np.savez(d / "skinning.npz", weights=np.ones((3, 24), np.float32), rest_joints=np.zeros((24, 3), np.float32),
             rider_id=np.array("x"))
    with pytest.raises(UserError, match="weights are"):
        RiderAvatar.load(d)
    os.remove(d / "skinning.npz")
    with pytest.raises(UserError, match="missing .*skinning.npz"):
        RiderAvatar.load(d)
    (d / "rider.ply").write_bytes(b"ply\ngarbage")
    avatar.save_skinning(d)
    with pytest.raises(UserError):
        RiderAvatar.load(d)


def test_bad_poses_are_refused(avatar):
    with pytest.raises(UserError, match="must be"):
        avatar.pose(torch.eye(3).repeat(2, 23, 1, 1))
    bad = torch.eye(3, dtype=torch.float64).repeat(1, 24, 1, 1)
    bad[0, 3, 0, 0] = float("nan")
    with pytest.raises(UserError, match="non-finite"):
        avatar.pose(bad)


def test_cli_unknown_rider_fails_cleanly(tmp_path):
    r = subprocess.run([sys.executable, "-m", "splatting", "rider-avatar", "--id", "nobody", "--out", str(tmp_path / "a")],
                       cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 2 and "unknown rider id" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "a").exists()


def test_blender_import_of_a_rider_mesh(rider, tmp_path, fresh_scene):
    from addon.core import frames
    from addon.core.rider.rider_import import import_rider, read_colored_ply, srgb_to_linear
    from splatting.rider.body import export_rider

    path = export_rider(rider, str(tmp_path / "rider.ply"))
    v, f, c = read_colored_ply(path)
    assert np.allclose(v, rider.vertices.numpy(), atol=1e-6) and np.array_equal(f, rider.faces.numpy())
    assert np.allclose(c, rider.colors.numpy(), atol=0.5 / 255 + 1e-6)
    obj = import_rider(path)
    assert obj.name == "rider" and obj.pass_index == 4
    mesh = obj.data
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    assert np.allclose(frames.to_canonical(co.reshape(-1, 3)), rider.vertices.numpy(), atol=1e-5)
    col = np.empty(len(mesh.vertices) * 4, dtype=np.float32)
    mesh.color_attributes["Col"].data.foreach_get("color", col)
    assert np.allclose(col.reshape(-1, 4)[:, :3], srgb_to_linear(c), atol=1e-5)
    nodes = obj.active_material.node_tree.nodes
    assert any(n.bl_idname == "ShaderNodeVertexColor" and n.layer_name == "Col" for n in nodes)


def test_corrupt_rider_mesh_is_refused(tmp_path):
    pytest.importorskip("bpy")
    from addon.core.rider.rider_import import read_colored_ply
    from addon.core.script import UserError as BUserError
    p = tmp_path / "bad.ply"
    p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
                  b"property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                  b"end_header\n" + b"\0" * 20)
    with pytest.raises(BUserError, match="truncated"):
        read_colored_ply(str(p))
    with pytest.raises(BUserError, match="no rider mesh"):
        read_colored_ply(str(tmp_path / "none.ply"))


@pytest.mark.slow
def test_render_rider_views_end_to_end(rider, tmp_path):
    """Two ring views at 1 sample through the entry script; the body lands where the cameras say."""
    from PIL import Image

    from splatting.raster.camera import load_cameras
    from splatting.rider.body import export_rider

    mesh = export_rider(rider, str(tmp_path / "rider.ply"))
    out = tmp_path / "views"
    r = subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "render_rider.py"), "--mesh", mesh,
                        "--out", str(out), "--views", "0,9", "--samples", "1"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    cams, orbit = load_cameras(out / "cameras.json")
    assert abs(orbit[1] - rider.height_m / 2) < 0.05
    for i in (0, 9):
        mask = np.asarray(Image.open(out / "mask" / f"camera{i:04d}" / "0000.png")) > 0
        cam = cams[i]
        for j in ("pelvis", "spine2", "neck"):
            p = rider.joints[JOINT_INDEX[j]] @ cam.R.T + cam.T
            u, v = (cam.K[0, 0] * p[0] / p[2] + cam.K[0, 2]).item(), (cam.K[1, 1] * p[1] / p[2] + cam.K[1, 2]).item()
            assert mask[int(v), int(u)], (i, j)
    with open(out / "transforms.json") as f:
        assert len(json.load(f)["frames"]) == 36

"""Exact SH rotation: colour seen along R d after rotating == colour along d before, every band."""
import math

import pytest
import torch

from splatting.gaussians.sh import C1, sh_basis
from splatting.gaussians.sh_rotation import rotate_sh, sh_band_matrices, sh_rotation_matrix


def random_rotations(n, dtype, seed=0):
    """Uniform random rotations via normalised Gaussian quaternions (independent of roma)."""
    g = torch.Generator().manual_seed(seed)
    q = torch.nn.functional.normalize(torch.randn(n, 4, generator=g, dtype=dtype), dim=-1)
    w, x, y, z = q.unbind(-1)
    return torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).reshape(n, 3, 3)


def raw_colour(sh, d, degree):
    """sum_k sh[k] Y_k(d) without the +0.5/clamp, so every band shows."""
    return torch.einsum("nk,nkc->nc", sh_basis(d, degree), sh)


@pytest.mark.parametrize("dtype,tol", [(torch.float32, 2e-5), (torch.float64, 1e-10)])
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_rotated_coefficients_follow_the_rotation(dtype, tol, degree):
    n = 500
    g = torch.Generator().manual_seed(degree)
    R = random_rotations(n, dtype, seed=degree + 10)
    sh = torch.randn(n, (degree + 1) ** 2, 3, generator=g, dtype=dtype)
    d = torch.nn.functional.normalize(torch.randn(n, 3, generator=g, dtype=dtype), dim=-1)
    rotated = rotate_sh(sh, R)
    Rd = torch.einsum("nij,nj->ni", R, d)
    assert torch.allclose(raw_colour(rotated, Rd, degree), raw_colour(sh, d, degree), atol=tol, rtol=0)
    if degree > 0:  # and it is not trivially the identity
        assert not torch.allclose(rotated, sh, atol=1e-2)


def test_degree_one_is_the_rotated_vector():
    # band 1 of the INRIA basis is C1 * (-y, z, -x): coefficients (a, b, c) describe the linear
    # function d -> C1 * w.d with w = (-c, -a, b); rotating the lobe rotates w
    R = random_rotations(4, torch.float64, seed=3)
    sh = torch.randn(4, 4, 1, dtype=torch.float64)
    out = rotate_sh(sh, R)
    a, b, c = sh[:, 1, 0], sh[:, 2, 0], sh[:, 3, 0]
    w = torch.stack([-c, -a, b], -1)
    w2 = torch.einsum("nij,nj->ni", R, w)
    want = torch.stack([-w2[:, 1], w2[:, 2], -w2[:, 0]], -1)
    assert torch.allclose(out[:, 1:4, 0], want, atol=1e-12)
    assert torch.equal(out[:, 0], sh[:, 0])
    assert abs(C1 - 0.5 * math.sqrt(3 / math.pi)) < 1e-12


def test_band_matrices_form_a_representation():
    R1 = random_rotations(6, torch.float64, seed=1)
    R2 = random_rotations(6, torch.float64, seed=2)
    M1, M2, M12 = (sh_rotation_matrix(R, 3) for R in (R1, R2, R1 @ R2))
    eye = torch.eye(16, dtype=torch.float64)
    assert torch.allclose(M12, M1 @ M2, atol=1e-12)  # D(R1 R2) = D(R1) D(R2)
    assert torch.allclose(M1 @ M1.transpose(-1, -2), eye, atol=1e-12)  # orthogonal
    assert torch.allclose(sh_rotation_matrix(torch.eye(3, dtype=torch.float64), 3), eye, atol=1e-12)
    assert [tuple(D.shape) for D in sh_band_matrices(R1, 3)] == [(6, 3, 3), (6, 5, 5), (6, 7, 7)]


def test_batched_shapes_broadcast():
    R = random_rotations(5, torch.float32)
    sh = torch.randn(7, 16, 3)
    out = rotate_sh(sh, R[:, None])  # 5 poses x 7 Gaussians
    assert out.shape == (5, 7, 16, 3)
    assert torch.allclose(out[2], rotate_sh(sh, R[2]), atol=1e-6)


def test_rotating_scene_and_camera_together_keeps_the_image():
    rast = pytest.importorskip("splatting.raster.sparse")
    from splatting.bike.pose import rigid, transform_gaussians
    from splatting.raster.camera import Camera
    from splatting.gaussians.container import Gaussians

    g = torch.Generator().manual_seed(5)
    n = 150
    scene = Gaussians(means=torch.randn(n, 3, generator=g) * 0.3, quats=torch.randn(n, 4, generator=g),
                      log_scales=torch.randn(n, 3, generator=g) * 0.3 - 3.0,
                      opacity_logits=torch.randn(n, generator=g) + 1.0,
                      sh=torch.randn(n, 16, 3, generator=g) * 0.4)
    W = H = 48
    K = torch.tensor([[60.0, 0, W / 2], [0, 60.0, H / 2], [0, 0, 1]])
    cam = Camera(torch.eye(3), torch.tensor([0.0, 0.0, 2.5]), K, W, H)
    R = random_rotations(1, torch.float64, seed=9)[0]
    t = torch.tensor([0.3, -1.0, 2.0], dtype=torch.float64)
    moved = transform_gaussians(scene, rigid(R, t))
    Rf, tf = R.float(), t.float()
    cam2 = Camera(cam.R @ Rf.T, cam.T - cam.R @ Rf.T @ tf, K, W, H)
    before = rast.render_gaussians(scene, cam)["rgb"]
    after = rast.render_gaussians(moved, cam2)["rgb"]
    assert before.std() > 0.05  # something is in view
    assert (before - after).abs().max() < 1e-3
    # without rotating the SH the view-dependent colour would change visibly
    wrong = Gaussians(moved.means, moved.quats, moved.log_scales, moved.opacity_logits, scene.sh)
    assert (rast.render_gaussians(wrong, cam2)["rgb"] - before).abs().max() > 0.05

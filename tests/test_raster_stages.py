"""Each stage of the sparse rasterizer against the reference's stage, not only whole images:
projection (means2d, conics, radii), intersection (which pairs, with which alpha), compositing
(the same alphas give the same colour, alpha and depth)."""
import torch

from splatting.raster.camera import ring_camera
from splatting.raster.reference import alpha_reference, composite_reference, project_reference
from splatting.raster.sparse import composite, intersect, project

SIZE = 40


def scene(n=50, seed=0, opacity_shift=-1.5):
    """Gaussians in view with modest opacities (no pixel reaches the 1e-4 transmittance cut-off,
    so the intersection keeps every pair the reference has)."""
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=torch.float64) * 0.25 + torch.tensor([0.0, 0.5, 0.0], dtype=torch.float64)
    means[0, 2] = -11.995  # one Gaussian behind the near plane of view 0
    q = torch.randn(n, 4, generator=g, dtype=torch.float64)
    scales = torch.exp(torch.randn(n, 3, generator=g, dtype=torch.float64) * 0.4 - 3.2)
    opac = torch.sigmoid(torch.randn(n, generator=g, dtype=torch.float64) + opacity_shift)
    return means, q / q.norm(dim=-1, keepdim=True), scales, opac


def camera():
    return ring_camera(0.0, orbit_centre=(0.0, 0.5, 0.0), size=SIZE, focal=2084.97 * SIZE / 512 * 0.3,
                       dtype=torch.float64)


def test_projection_matches_reference():
    means, quats, scales, _ = scene()
    cam = camera()
    m2, conics, z, radii, _ = project(means, quats, scales, cam)
    rm2, rconics, rz, rradii, _ = project_reference(means, quats, scales, cam)
    assert rradii[0] == 0 and radii[0] == 0  # behind the near plane: culled by both
    vis = radii > 0
    assert vis.sum() > 30  # the comparison covers most of the scene
    assert torch.allclose(m2[vis], rm2[vis], atol=1e-9)
    assert torch.allclose(conics[vis], rconics[vis], rtol=1e-9, atol=1e-12)
    assert torch.allclose(z, rz, atol=1e-12)
    # radii: identical wherever the box is on screen (the reference does not clip to the image)
    assert (radii[vis] == rradii[vis]).all()


def test_intersection_pairs_are_the_reference_alphas():
    means, quats, scales, opac = scene()
    cam = camera()
    m2, conics, z, radii, boxes = project(means, quats, scales, cam)
    pix, gid, dx, dy, alpha_raw = intersect(m2, conics, opac, z, boxes, radii, SIZE, SIZE)
    ref = alpha_reference(m2, conics, radii, opac, SIZE, SIZE)  # (N, H, W)
    dense = torch.zeros_like(ref).flatten(1)
    dense[gid.long(), pix.long()] = alpha_raw.clamp_max(0.99)
    dense = dense.view_as(ref)
    contributes = dense >= 1.0 / 255.0
    assert contributes.sum() > 200
    assert torch.equal(contributes, ref > 0)  # the same (pixel, Gaussian) pairs
    assert torch.allclose(dense[contributes], ref[contributes], rtol=1e-9)
    # pairs are grouped by pixel and front to back inside a pixel
    assert (pix[1:] >= pix[:-1]).all()
    same = pix[1:] == pix[:-1]
    assert (z[gid[1:].long()][same] >= z[gid[:-1].long()][same]).all()


def test_compositing_matches_reference_on_the_same_alphas():
    means, quats, scales, opac = scene(opacity_shift=1.5)  # dense enough to hit the cut-off somewhere
    cam = camera()
    m2, conics, z, radii, boxes = project(means, quats, scales, cam)
    colors = torch.rand(len(means), 5, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    pairs = intersect(m2, conics, opac, z, boxes, radii, SIZE, SIZE)
    bg = torch.tensor([0.2, 0.3, 0.4], dtype=torch.float64)
    col, alpha, depth = composite(m2, conics, opac, colors, z, bg, pairs, SIZE, SIZE)
    ref_alpha = alpha_reference(m2, conics, radii, opac, SIZE, SIZE)
    rcol, ralpha, rdepth = composite_reference(ref_alpha, colors, z, radii, bg)
    assert ralpha.max() > 0.99  # some pixels are opaque: the cut-off matters here
    assert torch.allclose(alpha, ralpha, atol=1e-9)
    assert torch.allclose(col, rcol, atol=1e-9)
    assert torch.allclose(depth, rdepth, atol=1e-8)

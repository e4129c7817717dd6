"""`rasterization()`: the one functional entry for rendering Gaussians, in the spirit of gsplat's.

Shapes (N Gaussians, C cameras, K = (sh_degree + 1)**2 SH coefficients, F extra channels):
  means      (N, 3)      world frame, metres
  quats      (N, 4)      wxyz rotations (normalised here)
  scales     (N, 3)      standard deviations (not logs)
  opacities  (N,)        in [0, 1]
  colors     (N, K, 3)   SH coefficients (evaluated per camera from the view direction), or
             (N, 3)      plain RGB when sh_degree is None and colors is 2-D
  viewmats   (C, 4, 4)   world-to-camera, OpenCV axes (x right, y down, z forward): x_cam = R X + T
  Ks         (C, 3, 3)   pinhole intrinsics; any principal point, any width x height
  features   (N, F)      optional per-Gaussian channels composited with the same weights as the
                         colour: instance ids (one-hot), labels, albedo, normals ...
  backgrounds (C, 3) or (3,) optional colour under the first three channels

Returns (render_colors (C, H, W, 3 + F), render_alphas (C, H, W, 1), meta) where meta holds
"depths" (C, H, W) = sum_i w_i z_i (not divided by alpha), "means2d" (list of C (N, 2) tensors,
retain_grad'ed when they require grad: the densification strategy reads their .grad), "radii"
(C, N) and "backend" (which implementation ran).  Differentiable in every Gaussian input.

The per-camera work is splatting.raster.sparse.rasterize (projection -> intersection ->
compositing); splatting.raster.reference renders the same image from the formulas for tests.
"""
import torch

from splatting.gaussians.sh import rgb_to_sh0
from splatting.raster.camera import Camera
from splatting.raster.sparse import EPS2D, rasterize


def _cameras(viewmats, Ks, width, height):
    viewmats, Ks = torch.as_tensor(viewmats), torch.as_tensor(Ks)
    if viewmats.dim() == 2:
        viewmats = viewmats[None]
    if Ks.dim() == 2:
        Ks = Ks[None]
    if viewmats.shape[1:] != (4, 4) or Ks.shape[1:] != (3, 3) or len(viewmats) != len(Ks):
        raise ValueError(f"rasterization: viewmats (C, 4, 4) and Ks (C, 3, 3), got {tuple(viewmats.shape)} "
                         f"and {tuple(Ks.shape)}")
    return [Camera(v[:3, :3], v[:3, 3], K, int(width), int(height), f"camera{i:04d}")
            for i, (v, K) in enumerate(zip(viewmats, Ks))]


def viewmat(camera):
    """(4, 4) world-to-camera matrix of a splatting.raster.camera.Camera."""
    M = torch.eye(4, dtype=camera.R.dtype)
    M[:3, :3], M[:3, 3] = camera.R, camera.T
    return M


def rasterization(means, quats, scales, opacities, colors, viewmats, Ks, width, height, *, sh_degree=None,
                  features=None, backgrounds=None, near=0.01, eps2d=EPS2D, antialiased=False, backend=None):
    """Render N Gaussians into C cameras; see the module docstring for shapes.  eps2d: the low-pass
    (px^2), a number or one per Gaussian (N,); antialiased: the mip filter (rasterize's), a bool or a
    (N,) bool mask: models drawn as they were trained (training.record)."""
    cams = _cameras(viewmats, Ks, width, height)
    sh = colors
    if colors.dim() == 2:  # plain RGB: a degree-0 SH whose evaluation gives the colour back
        sh, sh_degree = rgb_to_sh0(colors)[:, None, :], 0
    if backgrounds is not None:
        backgrounds = torch.as_tensor(backgrounds).to(means)
        if backgrounds.dim() == 1:
            backgrounds = backgrounds.expand(len(cams), 3)
    extra = {} if features is None else {"features": features}
    if backend is not None:
        extra["backend"] = backend
    outs = [rasterize(means, quats, scales, opacities, sh, cam, None if backgrounds is None else backgrounds[i],
                      sh_degree=sh_degree, near=near, eps2d=eps2d, antialiased=antialiased, **extra) for i, cam in enumerate(cams)]
    chans = [torch.cat([o["rgb"], o["features"]], -1) if features is not None else o["rgb"] for o in outs]
    meta = {"depths": torch.stack([o["depth"] for o in outs]), "means2d": [o["means2d"] for o in outs],
            "radii": torch.stack([o["radii"] for o in outs]), "backend": outs[0].get("backend", "torch")}
    return torch.stack(chans), torch.stack([o["alpha"] for o in outs])[..., None], meta


def render_cameras(g, cameras, features=None, backgrounds=None, **kw):
    """rasterization() for a Gaussians container (log scales, logit opacities) and a list of Camera
    of one size."""
    sizes = {(c.width, c.height) for c in cameras}
    if len(sizes) != 1:
        raise ValueError(f"render_cameras: cameras of one size per call, got {sorted(sizes)}")
    (w, h), = sizes
    vm = torch.stack([viewmat(c).to(g.means.dtype) for c in cameras])
    Ks = torch.stack([c.K.to(g.means.dtype) for c in cameras])
    return rasterization(g.means, g.quats, g.scales, g.opacities, g.sh, vm, Ks, w, h, sh_degree=g.sh_degree,
                         features=features, backgrounds=backgrounds, **kw)

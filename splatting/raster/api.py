"""`rasterization()`: the one entry for rendering Gaussians, in the spirit of gsplat's.  Every
caller outside splatting/raster renders through it (tests/test_layers.py checks that nothing else
imports the dispatch, sparse.py, or the C++ wrappers); `rasterize` / `render_gaussians` /
`render_cameras` below only adapt a Camera or a Gaussians container to it.

Shapes (N Gaussians, C cameras, K = (sh_degree + 1)**2 SH coefficients, F extra channels):
  means      (N, 3)      world frame, metres
  quats      (N, 4)      wxyz rotations (normalised here)
  scales     (N, 3)      standard deviations (not logs)
  opacities  (N,)        in [0, 1]
  colors     (N, K, 3)   SH coefficients (evaluated per camera from the view direction), or
             (N, 3)      plain RGB when sh_degree is None and colors is 2-D
  viewmats   (C, 4, 4)   world-to-camera, OpenCV axes (x right, y down, z forward): x_cam = R X + T
  Ks         (C, 3, 3)   pinhole intrinsics; any principal point, any width x height
     or cameras=[Camera, ...] (splatting.raster.camera, one size) instead of viewmats, Ks, width, height
  features   (N, F)      optional per-Gaussian channels composited with the same weights as the
                         colour: instance ids (one-hot), labels, albedo, normals ...; or a list of
                         (N, F_i) parts, composited as their concatenation
  backgrounds (C, 3) or (3,) optional colour under the first three channels
  eps2d      number or (N,) the screen-space low-pass (px^2), one per model (training.record)
  antialiased bool or (N,) bool  the mip filter with opacity compensation
  groups     (ids (N,), G) optional: also each group's alpha rendered alone (amodal masks)
  depth      False: no depth channel; shade: a TileShade (relit renders, splatting/relight/render.py)

Returns (render_colors (C, H, W, 3 + F), render_alphas (C, H, W, 1), meta) where meta holds
"depths" (C, H, W) = sum_i w_i z_i (not divided by alpha; absent with depth=False), "means2d" (list
of C (N, 2) tensors, retain_grad'ed when they require grad: the densification strategy reads their
.grad), "radii" (C, N), "visible" (C, N), "group_alphas" (C, G, H, W) with groups, "backend" (which
implementation ran) and "batched" (whether the C cameras were rendered in one pass).  With
per_camera=True: a list of C dicts instead (rgb, alpha, depth, features, group_alpha, means2d,
radii, visible, backend: splatting.raster.sparse.rasterize's), no channel packed into another tensor.
Differentiable in every Gaussian input.

Several cameras (C > 1) on the tiled back end without a gradient are rendered in ONE pass of the
C++ back end: the projection and SH of every camera in one parallel loop over Gaussian blocks, each
Gaussian's camera-independent rotation and 3D covariance factor computed once for all cameras and
its projection and colour computed for up to 8 cameras at once, one a vector lane
(cpu_project.preprocess_cameras), then binning, tile lists and blending with threads over camera x
chunk and camera x tile (cpu_tiles.composite_cameras, csrc/tiles.cpp forward_cameras); each
camera's image is bit-identical to its render alone.  With a gradient (training renders one view
per step), groups or a tile shading, or on the torch back end, the cameras are rendered one by one.
A single camera is splatting.raster.sparse.rasterize's render (projection -> intersection ->
compositing); splatting.raster.reference renders the same image from the formulas for tests.
"""
import torch

from splatting.gaussians.sh import rgb_to_sh0
from splatting.raster.camera import Camera
from splatting.raster.constants import EPS2D, check_eps2d, eps2d_cat, eps2d_where  # noqa: F401  (the callers')
from splatting.raster.cpu_project import preprocess_cameras
from splatting.raster.cpu_tiles import TileShade, composite_cameras  # noqa: F401  (TileShade: the callers')
from splatting.raster.projection import antialias_opacities
from splatting.raster.sparse import rasterize as _rasterize_one
from splatting.raster.sparse import resolve_backend


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


def rasterization(means, quats, scales, opacities, colors, viewmats=None, Ks=None, width=None, height=None, *,
                  cameras=None, sh_degree=None, features=None, backgrounds=None, near=0.01, eps2d=EPS2D,
                  antialiased=False, backend=None, groups=None, depth=True, shade=None, per_camera=False):
    """Render N Gaussians into C cameras; see the module docstring for shapes and returns."""
    if (cameras is None) == (viewmats is None):
        raise ValueError("rasterization: give viewmats, Ks, width, height or cameras=, not both")
    cams = list(cameras) if cameras is not None else _cameras(viewmats, Ks, width, height)
    if not cams or len({(c.width, c.height) for c in cams}) != 1:
        raise ValueError(f"rasterization: one or more cameras of one size, got {[(c.width, c.height) for c in cams]}")
    sh = colors
    if colors.dim() == 2:  # plain RGB: a degree-0 SH whose evaluation gives the colour back
        sh, sh_degree = rgb_to_sh0(colors)[:, None, :], 0
    if backgrounds is not None:
        backgrounds = torch.as_tensor(backgrounds)
        if backgrounds.dim() == 2 and backgrounds.shape[0] != len(cams):
            raise ValueError(f"rasterization: backgrounds (C, 3) or (3,), got {tuple(backgrounds.shape)} for "
                             f"{len(cams)} cameras")
    kw = dict(sh_degree=sh_degree, near=near, eps2d=eps2d, features=features, antialiased=antialiased,
              backend=backend, groups=groups, depth=depth, shade=shade)
    batched = _one_pass(cams, means, backend, groups, shade, (means, quats, scales, opacities, sh, backgrounds),
                        features)
    if batched:
        outs, packed = _render_cameras_at_once(means, quats, scales, opacities, sh, cams, backgrounds, **kw)
        if not per_camera:  # the images are already (C, H, W, ...): no per-camera stacking
            meta = _pack_meta(outs, True)
            meta.update({"depths": packed[2]} if depth else {})
            return packed[0], packed[1], meta
    else:
        outs = [_rasterize_one(means, quats, scales, opacities, sh, cam,
                               None if backgrounds is None else backgrounds if backgrounds.dim() == 1 else backgrounds[i],
                               **kw) for i, cam in enumerate(cams)]
    if per_camera:
        return outs
    return _pack(outs, batched)


def _one_pass(cams, means, backend, groups, shade, tensors, features):
    """Whether C > 1 cameras go through the C++ back end's several-camera pass (forward only)."""
    if len(cams) < 2 or groups is not None or shade is not None or resolve_backend(backend, means) != "tiles":
        return False
    if features is not None:
        tensors = tensors + ((features,) if torch.is_tensor(features) else tuple(features))
    return not (torch.is_grad_enabled() and any(t is not None and t.requires_grad for t in tensors))


def _render_cameras_at_once(means, quats, scales, opacities, sh, cams, backgrounds, sh_degree, near, eps2d,
                            features, antialiased, backend, groups, depth, shade):
    """The per-camera dicts of sparse.rasterize, computed for all cameras in one C++ pass, and
    (render_colors, render_alphas, depths or None) of all cameras."""
    C, n = len(cams), means.shape[0]
    eps2d = check_eps2d(eps2d, n)
    means2d, conics, depths, colors, radii, boxes, visible = preprocess_cameras(means, quats, scales, sh, cams,
                                                                                sh_degree, near, eps2d)
    # the mip filter per camera (its conics): the same elementwise ops as one camera's, all at once
    mask = antialiased.expand(C, n) if torch.is_tensor(antialiased) else antialiased
    opac = antialias_opacities(opacities.expand(C, n), conics, eps2d, mask, "rasterization")
    fparts = [] if features is None else [features] if torch.is_tensor(features) else list(features)
    fparts = [f for f in fparts if f.shape[1] > 0]
    planes = [colors] + ([fparts] if fparts else []) + ([depths[..., None]] if depth else [])
    bg = None if backgrounds is None else backgrounds.expand(C, 3)
    images, alpha = composite_cameras(means2d, conics, opac.expand(C, n), planes, depths, radii, boxes,
                                      cams[0].height, cams[0].width, bg)
    outs = []
    for c in range(C):
        o = {"rgb": images[0][c], "alpha": alpha[c], "means2d": means2d[c], "radii": radii[c],
             "visible": visible[c], "backend": "tiles"}
        if depth:
            o["depth"] = images[-1][c]
        if fparts:
            o["features"] = images[1][c]
        outs.append(o)
    colors_all = torch.cat([images[0], images[1]], -1) if fparts else images[0]
    return outs, (colors_all, alpha[..., None], images[-1] if depth else None)


def _pack(outs, batched):
    chans = [torch.cat([o["rgb"], o["features"]], -1) if "features" in o else o["rgb"] for o in outs]
    meta = _pack_meta(outs, batched)
    if "depth" in outs[0]:
        meta["depths"] = torch.stack([o["depth"] for o in outs])
    if "group_alpha" in outs[0]:
        meta["group_alphas"] = torch.stack([o["group_alpha"] for o in outs])
    return torch.stack(chans), torch.stack([o["alpha"] for o in outs])[..., None], meta


def _pack_meta(outs, batched):
    return {"means2d": [o["means2d"] for o in outs], "radii": torch.stack([o["radii"] for o in outs]),
            "visible": torch.stack([o["visible"] for o in outs]), "backend": outs[0]["backend"],
            "batched": batched}


def rasterize(means, quats, scales, opacities, sh, camera, background=None, **kw):
    """rasterization() for one Camera, returning its dict (rgb (H,W,3), alpha, depth, means2d,
    radii, visible, backend, and features / group_alpha when asked for)."""
    return rasterization(means, quats, scales, opacities, sh, cameras=[camera], backgrounds=background,
                         per_camera=True, **kw)[0]


def render_gaussians(g, camera, **kw):
    """rasterize() for a splatting.gaussians.Gaussians (log scales, logit opacities)."""
    return rasterize(g.means, g.quats, g.scales, g.opacities, g.sh, camera, **kw)


def render_cameras(g, cameras, features=None, backgrounds=None, **kw):
    """rasterization() for a Gaussians container (log scales, logit opacities) and a list of Camera
    of one size."""
    sizes = {(c.width, c.height) for c in cameras}
    if len(sizes) != 1:
        raise ValueError(f"render_cameras: cameras of one size per call, got {sorted(sizes)}")
    return rasterization(g.means, g.quats, g.scales, g.opacities, g.sh, cameras=cameras, sh_degree=g.sh_degree,
                         features=features, backgrounds=backgrounds, **kw)

"""The rasterizer's one-camera dispatch (internal: callers render through splatting.raster.api's
rasterization()): `rasterize(...)` renders N Gaussians into one camera by one of two back ends; see
docs/rasterizer.md.  Shapes (N Gaussians, K SH coeffs):
  means (N,3) world, quats (N,4) wxyz (normalised here), scales (N,3) std devs,
  opacities (N,) in [0,1], sh (N,K,3); camera: splatting.raster.camera.Camera.
eps2d: the screen-space low-pass (px^2) added to every projected covariance: a number, or a (N,)
tensor (each Gaussian its own: a scene composing models trained with different filters).
Returns a dict: rgb (H,W,3), alpha (H,W), depth (H,W), means2d (N,2) pixel coords (retain_grad'ed
when it requires grad: the densifier reads its .grad), radii (N,) long, visible (N,) bool.
depth = sum_i w_i z_i with w_i = alpha_i T_i and z_i the camera z: NOT divided by alpha (the
background counts as depth 0); depth / alpha.clamp_min(eps) is the normalised expected depth.

The rasterizer in four modules:
  constants.py        ALPHA_MIN/MAX, T_MIN, EPS2D and the eps2d rules;
  projection.py       project() (EWA, per Gaussian, autograd) and the mip filter's compensation;
  torch_composite.py  the torch reference: intersect() (sparse (pixel, Gaussian) list, no grad) ->
                      composite() (segmented front-to-back scan with a hand-written backward);
  sparse.py (here)    the dispatch: "tiles" (default for CPU tensors) projects and evaluates SH in
                      C++ (cpu_project.py) and composites with the fused tiled OpenMP compositor
                      (cpu_tiles.py); "torch" (the reference, CUDA tensors) the two above.
Its names stay importable from here.
"""
import torch

from splatting.gaussians.sh import eval_sh
from splatting.raster.constants import (ALPHA_MAX, ALPHA_MIN, CHUNK_PAIRS, EPS2D, T_MIN,  # noqa: F401  (re-exported)
                                        check_eps2d, eps2d_cat, eps2d_where)
from splatting.raster.cpu_project import preprocess
from splatting.raster.cpu_tiles import composite_tiles
from splatting.raster.projection import aa_compensation, antialias_opacities, project  # noqa: F401  (re-exported)
from splatting.raster.torch_composite import _group_alpha_torch, composite, intersect  # noqa: F401  (re-exported)
from splatting.rotations import quat_to_rotmat  # noqa: F401  (re-exported)


def rasterize(means, quats, scales, opacities, sh, camera, background=None, sh_degree=None,
              near=0.01, eps2d=EPS2D, features=None, antialiased=False, backend=None, groups=None, depth=True,
              shade=None):
    """Render N Gaussians into camera. See the module docstring for shapes.

    features: optional (N, F) extra channels composited like the colour (instance ids, albedo,
    normals...; background 0), returned as out["features"] (H, W, F); or a list of (N, F_i)
    parts, composited as their concatenation (the tiled back end reads the parts as they are:
    no (N, F) table is built per render).
    depth: False leaves the depth channel out (out has no "depth"): one channel less for the
    compositor to blend, for renders that do not use it (relit shading, splatting/relight/render.py).
    antialiased: mip-splatting's 2D filter with opacity compensation (gsplat's "antialiased"
    mode): opacity x sqrt(det S / det(S + eps2d I)), S the projected covariance before the eps2d
    low-pass, so a Gaussian smaller than a pixel keeps its true footprint instead of growing
    to a 0.3 px^2 blob at full opacity (thin spokes, far-away cyclists).  A (N,) bool tensor
    applies it to those Gaussians only (a scene mixing assets trained with and without it: each
    is drawn as it was trained).
    groups: optional (ids (N,) int in [-1, G), G): also out["group_alpha"] (G, H, W), the alpha of
    each group's Gaussians rendered alone (no occlusion by the other Gaussians: amodal masks), not
    differentiable; "tiles" computes them in the image's own pass, "torch" renders each group.
    shade: a splatting.raster.cpu_tiles.TileShade (tiled back end, float32, no grad, depth=False,
    no background; splatting/relight/render.py builds it): each tile is shaded as the compositor
    finishes it, out["rgb"] is the display colour shaded from the composited colour (the
    reflectance) and features, and out["features"] is there only when shade.features.
    backend: "tiles" (the fused OpenMP C++ compositor, splatting/raster/cpu_tiles.py; CPU tensors),
    "torch" (the pure-torch pair list below: the reference, and the path for CUDA tensors), or
    None: "tiles" for CPU tensors, "torch" otherwise. out["backend"] says which one ran."""
    H, W = camera.height, camera.width
    backend = resolve_backend(backend, means)
    eps2d = check_eps2d(eps2d, means.shape[0])
    if shade is not None and (backend != "tiles" or depth):
        raise ValueError("rasterize: shade needs the tiled back end and depth=False")
    if backend == "tiles":  # projection + SH fused in C++ (splatting/raster/cpu_project.py)
        means2d, conics, depths, colors, radii, boxes, visible = preprocess(means, quats, scales, sh, camera,
                                                                            sh_degree, near, eps2d)
    else:
        means2d, conics, depths, radii, boxes = project(means, quats, scales, camera, near, eps2d)
        centre = camera.centre.to(means.device, means.dtype)
        dirs = means - centre
        dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        colors = eval_sh(sh, dirs, sh_degree)
        visible = radii > 0
    if means2d.requires_grad:
        means2d.retain_grad()
    opacities = antialias_opacities(opacities, conics, eps2d, antialiased, "rasterize")
    if features is not None and not torch.is_tensor(features):  # parts
        features = list(features)
        nf = sum(f.shape[1] for f in features)
        if backend == "torch" and features:
            features = torch.cat(features, 1)
    else:
        nf = 0 if features is None else features.shape[1]
    group_alpha = None
    want_depth = depth
    if backend == "tiles":
        rgb, alpha, depth, feats, group_alpha = _composite_tiles(means2d, conics, opacities, colors, features, depths,
                                                                 radii, boxes, background, H, W, groups, want_depth,
                                                                 shade)
    else:
        if nf:
            colors = torch.cat([colors, features.to(colors)], 1)
        pairs = intersect(means2d.detach(), conics.detach(), opacities.detach(), depths.detach(), boxes, radii, W, H)
        col, alpha, depth = composite(means2d, conics, opacities, colors, depths, background, pairs, H, W)
        rgb, feats = col[..., :3], col[..., 3:]
        if groups is not None:
            group_alpha = _group_alpha_torch(means2d, conics, opacities, depths, radii, boxes, groups, H, W)
    out = {"rgb": rgb, "alpha": alpha, "depth": depth, "means2d": means2d, "radii": radii,
           "visible": visible, "backend": backend}
    if not want_depth:
        del out["depth"]
    if nf and feats is not None:
        out["features"] = feats
    if groups is not None:
        out["group_alpha"] = group_alpha
    return out


# ---------------------------------------------------------------- back-end choice (tiled C++ / torch)

BACKENDS = ("tiles", "torch")


def resolve_backend(backend, means):
    """None -> "tiles" for CPU tensors, "torch" for others; anything else must be in BACKENDS."""
    if backend is None:
        return "tiles" if means.device.type == "cpu" else "torch"
    if backend not in BACKENDS:
        raise ValueError(f"rasterize: backend must be one of {BACKENDS} or None, got {backend!r}")
    return backend


def _composite_tiles(means2d, conics, opacities, colors, features, depths, radii, boxes, background, H, W,
                     groups=None, depth=True, shade=None):
    """The tiled C++ compositor with the torch path's outputs: rgb (H,W,3) over the background,
    alpha, depth (camera z composited as the last channel; None when not depth), features (H,W,F)
    or None, features a tensor or a list of parts (one plane). Colour,
    features and depth are handed over as separate planes; the compositor reads them in place,
    writes each as its own contiguous image (colour already over the background, alpha, the
    group alphas), and takes their gradients back the same way (no concatenation, no slicing, no
    torch op on a full image)."""
    fparts = [] if features is None else [features] if torch.is_tensor(features) else list(features)
    fparts = [f.to(colors) for f in fparts if f.shape[1] > 0]
    planes = [colors] + ([fparts[0] if len(fparts) == 1 else fparts] if fparts else []) + ([depths] if depth else [])
    res = composite_tiles(means2d, conics, opacities, planes, depths.detach(), radii, boxes, H, W,
                          *(() if groups is None else groups), background=background, shade=shade)
    rgb, alpha = res[0], res[len(planes)]
    feats = res[1] if fparts else None
    return rgb, alpha, res[len(planes) - 1] if depth else None, feats, None if groups is None else res[-1]


def render_gaussians(g, camera, **kw):
    """rasterize() for a splatting.gaussians.Gaussians (log scales, logit opacities)."""
    return rasterize(g.means, g.quats, g.scales, g.opacities, g.sh, camera, **kw)

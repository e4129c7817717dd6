"""Relit rendering: the reflectance, normals and gloss composited by the rasterizer, shaded per pixel.

`render_relit` is one rasterizer call (rasterize(features=...), the tiled C++ compositor).
`prepare` / `composite_features` keep the pure-torch pair list for the relight fit, which needs the
backward of the features with the geometry fixed (one projection per view, reused every step).
"""
import math
from typing import NamedTuple, Optional
import ctypes

import torch

from splatting.gaussians.container import Gaussians
from splatting.gaussians.sh import rgb_to_sh0
from splatting.raster import build
from splatting.raster.api import EPS2D, TileShade, render_gaussians
# the relight fit's fixed pair list: the torch compositor's stages, reused across iterations
from splatting.raster.projection import antialias_opacities, project
from splatting.raster.torch_composite import composite, intersect
from splatting.relight.shading import HIGHLIGHT, ROUGHNESS, Light, _shade_cm, _view_directions_cm
from splatting.relight import shadow  # shadow.X at call time: the maps are swapped in tests

LUMA = torch.tensor([0.2126, 0.7152, 0.0722])  # Rec. 709 luminance of linear RGB


def prepare(g, camera, antialiased=False, eps2d=EPS2D):
    """Projection + pair list of Gaussians g for camera (no grad): what every channel reuses.
    antialiased: the rasterizer's mip filter (rasterize(antialiased=...): a bool, or a (N,) bool mask
    of the Gaussians it applies to), for Gaussians trained with it: their opacities are scaled by the
    filter's compensation as the rasterizer does, or the fit composites other alphas than the render."""
    with torch.no_grad():
        means = g.means.float().contiguous()
        opac = g.opacities.float().contiguous()
        m2, conics, z, radii, boxes = project(means, g.quats.float(), g.scales.float(), camera, eps2d=eps2d)
        opac = antialias_opacities(opac, conics, eps2d, antialiased, "prepare").contiguous()
        pairs = intersect(m2, conics, opac, z, boxes, radii, camera.width, camera.height)
    return {"m2": m2, "conics": conics, "opac": opac, "z": z, "pairs": pairs, "H": camera.height, "W": camera.width}


def composite_features(prep, features):
    """features: list of (N, 3) tensors -> list of premultiplied (H, W, 3) images, and alpha (H, W).
    Differentiable in the features (the geometry in prep is fixed)."""
    outs, alpha = [], None
    for f in features:
        img, a, _ = composite(prep["m2"], prep["conics"], prep["opac"], f.to(prep["m2"].dtype), prep["z"], None,
                              prep["pairs"], prep["H"], prep["W"])
        outs.append(img)
        alpha = a
    return outs, alpha


def gloss_luma(gloss):
    """(N, 3) gloss -> (N, 1) its Rec. 709 luminance (the channel shade_composited reads)."""
    return (gloss.float() @ LUMA)[:, None]


def relight_feature_parts(normals, luma=None, roughness=None, visibility=None, sky_visibility=None):
    """relight_features' columns as a list of (N, c) float32 parts (luma: gloss_luma(gloss)), for
    rasterize(features=[...]), which composites them without concatenating them."""
    cols = [normals.float()]
    if luma is not None:
        cols.append(luma.float())
    for x in (roughness, visibility, sky_visibility):
        if x is not None:
            cols.append(x.float().reshape(-1, 1))
    return cols


def relight_features(normals, gloss=None, roughness=None, visibility=None, sky_visibility=None):
    """The per-Gaussian channels shade_composited reads, as one (N, C) float32 table: the world
    normal (3), then the gloss's luminance (1) when there is a gloss, a per-Gaussian roughness (1)
    when given (scenes mixing materials: a bike's 0.4, a rider's 1.0), the sun visibility (1) when
    given (cast shadows), the sky visibility (1) when given (self-occlusion, shadow.sky_visibility).
    The reflectance albedo + gloss is composited through the colour channels (or its own 3
    features, splatting/cyclist/scene_relit.py)."""
    luma = None if gloss is None else gloss_luma(gloss)
    return torch.cat(relight_feature_parts(normals, luma, roughness, visibility, sky_visibility), 1).contiguous()


class RelitStatic(NamedTuple):
    """What render_relit derives from the pose-invariant albedo and gloss (relit_static): a
    relightable bike or avatar keeps it (RelightableBike.static), so no render rebuilds it."""
    sh: torch.Tensor                      # (N, 1, 3) the reflectance albedo + gloss as degree-0 SH
    gloss_luma: Optional[torch.Tensor]    # (N, 1) gloss_luma(gloss), None without a gloss


def relit_static(albedo, gloss=None):
    refl = albedo.float() if gloss is None else albedo.float() + gloss.float()
    return RelitStatic(rgb_to_sh0(refl)[:, None, :].contiguous(), None if gloss is None else gloss_luma(gloss))


def shade_composited(R, feats, alpha, camera, light: Light, gloss=True, rough_channel=False, shadows=False,
                     roughness=ROUGHNESS, highlight=HIGHLIGHT, box=None, backend=None, in_place=False,
                     sky_channel=False):
    """Display colour of composited relight channels: R (H, W, 3) the premultiplied reflectance
    albedo + gloss, feats (H, W, C) the composited relight_features (same flags), alpha (H, W) the
    coverage of what they came from, camera the view they were rendered in (for the highlight's
    view directions) -> rgb (H, W, 3) premultiplied over black.  Only covered pixels are shaded
    (alpha > 1e-5; an object fills a fraction of its image), and only inside box (u0, v0, u1, v1)
    when given.  backend "c": the fused per-pixel loop of csrc/shade.cpp (float32 CPU; one pass
    instead of ~80 torch operations: 0.2 vs 4-9 ms for a bike's 22k pixels at 512 px), "torch":
    the same formula as torch operations (splatting/relight/shading.py, the reference the tests
    hold the C to); None: "c" for float32 CPU tensors, else "torch".
    in_place: the colour overwrites R (a contiguous image, 0 wherever alpha is 0, as the
    compositor leaves it; no box) and R is returned: no image to allocate and fill, and the C loop
    writes only the covered pixels (at 512 px a bike covers ~10 % of them)."""
    H, W = alpha.shape
    u0, v0, u1, v1 = box if box is not None else (0, 0, W, H)
    if backend is None:
        backend = "c" if feats.dtype == torch.float32 and feats.device.type == "cpu" else "torch"
    if in_place and (box is not None or not R.is_contiguous()):
        raise ValueError("shade_composited: in_place needs a contiguous R and no box")
    # the C loop writes every pixel of its box (zeros where uncovered): no zero fill for the whole image
    whole = backend == "c" and (u0, v0, u1, v1) == (0, 0, W, H)
    if backend == "c":
        rgb = R.view(H * W, 3) if in_place else (torch.empty if whole else torch.zeros)(H * W, 3, dtype=feats.dtype)
        _shade_c((u0, v0, u1, v1), R, feats, alpha, rgb, camera, light, gloss, rough_channel, shadows, roughness,
                 highlight, in_place, sky_channel)
        return rgb.reshape(H, W, 3)
    rgb = torch.zeros(H * W, 3, dtype=feats.dtype)
    if backend != "torch":
        raise ValueError(f"shade_composited: backend must be 'c', 'torch' or None, got {backend!r}")
    ys, xs = torch.nonzero(alpha[v0:v1, u0:u1] > 1e-5, as_tuple=True)
    ys, xs = ys + v0, xs + u0
    pix = ys * W + xs  # flat indices: the channels' flat (H W, C) reshapes are views, so no copies
    # channel-major from here (splatting/relight/shading.py: the row-wise dots are 5x faster)
    f = feats.reshape(H * W, -1).index_select(0, pix).T.contiguous()
    a = alpha.reshape(-1).index_select(0, pix)
    Rp = R.reshape(H * W, 3).index_select(0, pix).T.contiguous()
    nrm, c = f[:3], 3
    gl, alb = None, Rp
    if gloss:
        # per pixel the gloss colour is the reflectance's tint times the composited gloss luminance
        # (exact for grey gloss: metals, clear coats)
        L = LUMA.tolist()
        lum = (Rp[0] * L[0]).add_(Rp[1], alpha=L[1]).add_(Rp[2], alpha=L[2]).clamp_min_(1e-6)
        gl = Rp * (f[c] / lum).clamp_(0, 1)
        alb, c = Rp - gl, c + 1
    if rough_channel:
        roughness, c = (f[c] / a.clamp_min(1e-6)).clamp_(0.05, 1.0), c + 1
    vis, c = ((f[c] / a.clamp_min(1e-6)).clamp_(0, 1), c + 1) if shadows else (None, c)
    sky = (f[c] / a.clamp_min(1e-6)).clamp_(0, 1) if sky_channel else None
    view = _view_directions_cm(camera, ys, xs, f.dtype) if gloss else None
    rgb.index_copy_(0, pix, _shade_cm(alb, nrm, a, light, gl, view, roughness, highlight, vis, sky).T)
    return R.copy_(rgb.reshape(H, W, 3)) if in_place else rgb.reshape(H, W, 3)


_C = None


def _shade_c(box, R, feats, alpha, out, camera, light, gloss, rough_channel, shadows, roughness, highlight,
             in_place=False, sky_channel=False):
    """csrc/shade.cpp's rl_shade_f32 on the rasterizer's pixel-major views (no gathers, no copies)."""
    global _C
    if _C is None:
        _C = build.load().rl_shade_f32
        i64, p = ctypes.c_int64, ctypes.c_void_p
        _C.argtypes, _C.restype = [i64, i64, i64, i64, i64, p, i64, p, i64, p, p, p, ctypes.c_int32], None
    H, W = alpha.shape
    # each pixel's channels contiguous, pixels evenly strided (the compositor's (H, W, C) table)
    R = R if R.stride(2) == 1 and R.stride(0) == W * R.stride(1) else R.contiguous()
    feats = feats if feats.stride(2) == 1 and feats.stride(0) == W * feats.stride(1) else feats.contiguous()
    alpha = alpha.contiguous()
    prm = shade_params(camera, light, roughness, highlight)
    _C(W, *box, R.data_ptr(), R.stride(1), feats.data_ptr(), feats.stride(1), alpha.data_ptr(), out.data_ptr(),
       prm.data_ptr(), shade_flags(gloss, rough_channel, shadows, sky_channel) | 8 * int(in_place))


def shade_params(camera, light: Light, roughness=ROUGHNESS, highlight=HIGHLIGHT):
    """csrc/shade.cpp's parameters (24,) float32: the sun direction, sun colour x strength, sky,
    fx, fy, cx, cy, the world-to-camera rotation, roughness (0 when a tensor: then a channel), highlight.
    In Python floats, with two tensor reads and one tensor made: as ~15 small torch operations
    (Light.direction, indexing K) it took 0.2-0.25 ms of each relit render (cold, between renders;
    30 us in a tight loop), a fifth of what a relit render costs over a baked one."""
    (fx, _, cx), (_, fy, cy), _ = camera.K.tolist()
    d = [float(v) for v in light.sun_direction]
    n = max(math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), 1e-12)  # Light.direction's normalisation
    return torch.tensor([d[0] / n, d[1] / n, d[2] / n, *[c * light.sun_strength for c in light.sun_colour], *light.sky,
                         fx, fy, cx, cy, *camera.R.reshape(-1).tolist(),
                         0.0 if torch.is_tensor(roughness) else float(roughness), float(highlight)], dtype=torch.float32)


def shade_flags(gloss, rough_channel=False, shadows=False, sky_channel=False):
    """csrc/shade.cpp's flags: which feature channels follow the normal (shade_composited's order)."""
    return int(gloss) | 2 * int(rough_channel) | 4 * int(shadows) | 16 * int(sky_channel)


def view_normals(normals, normal_view, means, camera):
    """View-dependent normals: (N, 3) normalize(normals + normal_view @ v), v each Gaussian's unit
    direction to the camera's centre (N, 3).  normal_view (N, 3, 3) in the normals' frame
    (RelightableBike.posed_normal_view: world).  Why: a Gaussian across a thin tube shows the mean
    normal of the tube's visible half, which turns with the view: for a cylinder of axis a it is
    normalize((I - a a^T) v), which normal_view = k (I - a a^T) gives exactly; a flat splat has
    normal_view = 0 (fit.RelightFitConfig.view_normals, docs/relighting.md).  Without gradients on
    float32 CPU tensors one C pass (csrc/shade.cpp rl_view_normals_f32: ~10x faster than the torch
    operations, which the fit differentiates)."""
    c = camera.centre.to(means.dtype).reshape(1, 3)
    xs = (normals, normal_view, means)
    if all(x.dtype == torch.float32 and x.device.type == "cpu" for x in xs) and not (
            torch.is_grad_enabled() and any(x.requires_grad for x in xs)):
        return _view_normals_c(*xs, c)
    v = c - means
    v = v / v.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    n = torch.baddbmm(normals.to(means.dtype)[:, :, None], normal_view.to(means.dtype), v[:, :, None])[:, :, 0]
    return n / n.norm(dim=-1, keepdim=True).clamp_min(1e-6)


def leading_view_normals(normals, normal_view, means, camera):
    """normals (N, 3) of a scene whose first len(normal_view) Gaussians (a cyclist's bike) have
    view-dependent normals, those turned to camera (view_normals), the rest as they are."""
    nb = len(normal_view)
    return torch.cat([view_normals(normals[:nb], normal_view, means[:nb].float(), camera), normals[nb:]])


_VN = None


def _view_normals_c(normals, normal_view, means, c):
    global _VN
    if _VN is None:
        _VN = build.load().rl_view_normals_f32
        _VN.argtypes, _VN.restype = [ctypes.c_int64] + [ctypes.c_void_p] * 5, None
    normals, normal_view, means, c = (x.contiguous() for x in (normals, normal_view, means, c))
    out = torch.empty_like(normals)
    _VN(len(normals), normals.data_ptr(), normal_view.data_ptr(), means.data_ptr(), c.data_ptr(), out.data_ptr())
    return out


@torch.no_grad()
def render_relit(g, albedo, normals, camera, light: Light, gloss=None, roughness=ROUGHNESS, highlight=HIGHLIGHT,
                 shadows=False, antialiased=True, static=None, reflectance=False, sky_visibility=None, normal=False,
                 fused=None, shadow_antialiased=False, normal_view=None, eps2d=EPS2D):
    """Gaussians g with per-Gaussian linear albedo (N, 3), world-frame unit normals (N, 3) and optionally
    a linear glossy colour (N, 3) under a light -> dict rgb (H, W, 3) display colour premultiplied
    (over black), alpha, with normal=True the composited normal and with reflectance=True the
    composited reflectance albedo + gloss.  One rasterizer call composites every channel
    (rasterize(features=...)).  fused (None: whenever the tiled back end runs on float32 and
    reflectance is False): the compositor shades each tile as it finishes it (rasterize(shade=...),
    csrc/shade.cpp rl_shade_tile_f32), so no reflectance or feature image is written and read
    back (the normal is written only when asked for); False: composite, then shade_composited in
    place over the reflectance (the two-pass path; the torch back end's).  The gloss reflects the sky and shows the sun's
    highlight (splatting/relight/shading.py).  shadows: the sun is blocked per Gaussian by the
    others (splatting/relight/shadow.py: one more render, from the sun).  antialiased: the
    rasterizer's mip filter (keeps sub-pixel Gaussians -- spokes, cables -- their true coverage
    when rendered below their training resolution; mask IoU 0.795 -> 0.892 for a 512 px-trained
    bike at 256 px, bench/relight.py).  static: relit_static(albedo, gloss) kept by the caller
    (RelightableBike.static): albedo and gloss are then not read; None derives it here.
    sky_visibility (N,): each Gaussian's share of the sky (splatting/relight/shadow.py
    sky_visibility; a bike's: RelightableBike.sky_visibility), one more composited channel; None:
    the sky reaches everything.  shadow_antialiased: the mip filter in the sun's shadow map
    (shadow.sun_visibility), for Gaussians trained with it (BikeModel.antialiased; a bool or (N,)
    mask) whatever the view's `antialiased` (which also serves rendering below the training size).
    normal_view (N, 3, 3) world frame (RelightableBike.posed_normal_view): view-dependent normals,
    view_normals(normals, normal_view, g.means, camera); None: normals as they are.
    eps2d: rasterize's low-pass, a number or (N,), as g was trained (BikeModel.eps2d), view and
    shadow map alike."""
    # Channel budget (each composited channel costs the tiled compositor ~3-5 % of a render): the
    # reflectance albedo + gloss rides in the colour channels (degree-0 SH whose colour is it), the
    # normal and the gloss's luminance are the features (relight_features), handed over as parts
    # (no table built per render), and no depth is composited.
    static = relit_static(albedo, gloss) if static is None else static
    if static.sh.shape != (len(g), 1, 3):
        raise ValueError(f"render_relit: static channels for {static.sh.shape[0]} Gaussians, not {len(g)}")
    if normal_view is not None:
        normals = view_normals(normals, normal_view, g.means, camera)
    vis = None
    if shadows:
        vis = shadow.sun_visibility(g, light, antialiased=shadow_antialiased, eps2d=eps2d)
    gr = Gaussians(g.means, g.quats, g.log_scales, g.opacity_logits, static.sh)
    parts = relight_feature_parts(normals, static.gloss_luma, visibility=vis, sky_visibility=sky_visibility)
    gloss_on, sky_on = static.gloss_luma is not None, sky_visibility is not None
    can_fuse = not reflectance and g.means.dtype == torch.float32 and g.means.device.type == "cpu" \
        and not torch.is_tensor(roughness)
    if fused and not can_fuse:
        raise ValueError("render_relit: fused shading needs float32 CPU Gaussians, a scalar roughness and "
                         "reflectance=False")
    if can_fuse and fused is not False:

        spec = TileShade(shade_params(camera, light, roughness, highlight),
                         shade_flags(gloss_on, False, shadows, sky_on), features=normal)
        r = render_gaussians(gr, camera, features=parts, sh_degree=0, antialiased=antialiased, depth=False,
                             backend="tiles", shade=spec, eps2d=eps2d)
        out = {"rgb": r["rgb"], "alpha": r["alpha"]}
    else:
        r = render_gaussians(gr, camera, features=parts, sh_degree=0, antialiased=antialiased, depth=False, eps2d=eps2d)
        rgb = shade_composited(r["rgb"], r["features"], r["alpha"], camera, light, gloss_on, False, shadows,
                               roughness, highlight, in_place=not reflectance, sky_channel=sky_on)
        out = {"rgb": rgb, "alpha": r["alpha"]}
        if reflectance:
            out["reflectance"] = r["rgb"]
    if normal:
        out["normal"] = r["features"][..., :3]
    return out

"""Per-pixel shading of composited albedo and normal under a sun plus a uniform sky (docs/relighting.md).

Units follow Blender's Cycles so that a light set up here and in Blender renders alike: a sun of
strength E (W/m^2) lights a Lambertian surface of albedo a, normal n with outgoing radiance
a E max(0, n.l) / pi (measured: a 0.5-albedo plane facing a strength-1 sun renders 0.163 in the
Combined pass, 1/pi = 0.318 per unit albedo plus a little specular); a uniform world colour of
radiance L (Blender's background colour x strength) adds a L whatever the normal (the whole sphere
lights the surface; self-occlusion is not modelled).  Shading happens in linear light; the
display image is the sRGB encoding of the straight colour, as Blender's "Standard" view transform.

The glossy colour (Cycles' Glossy Color pass) is shaded like the albedo: exact for the uniform sky
(a glossy lobe returns its directional albedo from a uniform environment), a diffuse-like average
for the sun (no highlight), so callers pass albedo + gloss as `albedo`.

Inputs are premultiplied by coverage, as the rasterizer composites them: albedo (H, W, 3) linear,
normal (H, W, 3) the composited unit normals (its direction is the pixel's normal), alpha (H, W).
"""
import math
from dataclasses import dataclass

import numpy as np
import torch


@dataclass
class Light:
    sun_direction: tuple = (0.4, 0.6, 1.0)   # towards the sun, canonical world frame (normalised here)
    sun_colour: tuple = (1.0, 1.0, 1.0)
    sun_strength: float = 3.0                 # W/m^2, as Blender's sun "Strength"
    sky: tuple = (0.48, 0.492, 0.51)          # world background radiance (colour x strength)

    def direction(self, dtype=torch.float32):
        d = torch.as_tensor(self.sun_direction, dtype=dtype)
        return d / d.norm().clamp_min(1e-12)


def random_light(rng, min_elevation_deg=15.0, strength=(2.0, 5.0), sky=(0.1, 0.6)):
    """A sun somewhere above the horizon (uniform azimuth, elevation in [min, 90]) with a random warm/cool
    tint and a grey-blue sky; rng: numpy Generator.  What bench/relight.py uses against Blender."""
    az = rng.uniform(0.0, 2 * math.pi)
    el = math.radians(rng.uniform(min_elevation_deg, 90.0))
    d = (math.cos(el) * math.cos(az), math.sin(el), math.cos(el) * math.sin(az))  # canonical: Y up
    tint = rng.uniform(0.85, 1.0, 3)
    s = rng.uniform(*sky)
    return Light(sun_direction=d, sun_colour=tuple(float(x) for x in tint / tint.max()),
                 sun_strength=float(rng.uniform(*strength)), sky=(0.92 * s, 0.96 * s, s))


def srgb_encode(x):
    """Linear -> sRGB-encoded (IEC 61966-2-1), torch; clamps to [0, 1]."""
    x = x.clamp(0.0, 1.0)
    return torch.where(x <= 0.0031308, 12.92 * x, 1.055 * x.clamp_min(1e-12) ** (1 / 2.4) - 0.055)


def srgb_decode(y):
    y = y.clamp(0.0, 1.0)
    return torch.where(y <= 0.04045, y / 12.92, ((y + 0.055) / 1.055) ** 2.4)


# The gloss under the sun (docs/relighting.md "Where the error goes"): a GGX highlight of this
# roughness, scaled by HIGHLIGHT.  Both were chosen with bench/relight_budget.py on Blender's own
# passes (poses and suns of seed 1, not the bench's): at 256 px the sun's highlight on a tube is a
# sub-pixel line whose place the pixel's averaged normal does not pin down, so the expected
# highlight (half the sharp one) beats the sharp one; a per-pixel roughness gained only 0.35 dB.
ROUGHNESS = 0.4
HIGHLIGHT = 0.25


def ggx_sun(normal, view, light: Light, roughness=ROUGHNESS, cos_l=None):
    """Sun radiance factor of a glossy surface per unit glossy colour: D_GGX(n.h) / (4 n.v) where
    n.l > 0 (Cook-Torrance with F G folded into the Glossy Color pass, which is the lobe's
    directional albedo).  normal, view: (..., 3) unit, view pointing to the camera; roughness one
    value or per pixel (...,); cos_l: n.l if the caller has it.  In-place ops on temporaries:
    this runs per covered pixel of every relit render (relight_render_overhead)."""
    l = light.direction(normal.dtype)
    h = view + l
    h.div_(torch.linalg.vector_norm(h, dim=-1, keepdim=True).clamp_min_(1e-6))
    nh = torch.linalg.vecdot(normal, h).clamp_(0.0, 1.0)
    nv = torch.linalg.vecdot(normal, view).clamp_min_(0.05)  # grazing pixels: the lobe's 1/(n.v) would explode
    a2 = roughness ** 4 if torch.is_tensor(roughness) else float(roughness) ** 4  # per pixel or one value
    t = nh.mul_(nh).mul_(a2 - 1.0).add_(1.0)  # n.h^2 (a2 - 1) + 1
    D = t.mul_(t).mul_(4.0 * math.pi).mul_(nv)  # 4 pi t^2 n.v: the denominator of D / (4 n.v)
    D = torch.reciprocal_(D).mul_(a2)
    cos = normal @ l if cos_l is None else cos_l
    return D.masked_fill_(cos <= 0, 0.0)


def shade_linear(albedo, normal, light: Light, gloss=None, view=None, roughness=ROUGHNESS, highlight=HIGHLIGHT,
                 sun_visibility=None):
    """Premultiplied linear radiance (H, W, 3) of premultiplied albedo and composited normals.

    gloss (premultiplied glossy colour) reflects the sky like the albedo (exact for a uniform sky)
    and the sun as a GGX highlight seen along `view` ((H, W, 3) unit, towards the camera); without
    a view it is shaded like the albedo (the diffuse-like approximation).  sun_visibility (H, W, 1)
    in [0, 1] scales the sun (cast shadows, splatting/relight/shadow.py); the sky is not occluded."""
    dt = albedo.dtype
    n = normal / torch.linalg.vector_norm(normal, dim=-1, keepdim=True).clamp_min_(1e-6)
    cos = (n @ light.direction(dt)).clamp_min_(0.0)
    sun = torch.as_tensor(light.sun_colour, dtype=dt) * light.sun_strength
    sky = torch.as_tensor(light.sky, dtype=dt)
    lit = cos[..., None] * (sun / math.pi)  # the sun's diffuse irradiance / pi, per channel
    if sun_visibility is not None:
        lit.mul_(sun_visibility)
    if gloss is None:
        return lit.add_(sky).mul_(albedo)
    if view is None:
        return lit.add_(sky).mul_(albedo + gloss)
    spec = ggx_sun(n, view, light, roughness, cos)[..., None] * (highlight * sun)
    if sun_visibility is not None:
        spec.mul_(sun_visibility)
    return lit.add_(sky).mul_(albedo).addcmul_(spec.add_(sky), gloss)


def view_directions(camera, dtype=torch.float32, pixels=None, rows_cols=None):
    """Unit vectors from each pixel's surface towards the camera (world frame): (H, W, 3), or (P, 3)
    for the flat pixel indices `pixels` (P,) or the pixels (rows (P,), cols (P,)) `rows_cols`."""
    H, W = camera.height, camera.width
    K = camera.K.to(torch.float64)
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    if rows_cols is not None:
        v, u = (x.to(dtype) for x in rows_cols)
    elif pixels is None:
        v, u = torch.meshgrid(torch.arange(H, dtype=dtype), torch.arange(W, dtype=dtype), indexing="ij")
    else:
        v, u = (pixels // W).to(dtype), (pixels % W).to(dtype)
    x, y = (u + (0.5 - cx)) / fx, (v + (0.5 - cy)) / fy
    R = camera.R.to(dtype)
    # the ray R^T (x, y, 1) in the world, as x R[0] + y R[1] + R[2] (three broadcasts, no matmul)
    d = x[..., None] * R[0] + R[2]
    d.addcmul_(y[..., None], R[1])
    return d.div_(-torch.linalg.vector_norm(d, dim=-1, keepdim=True))


def shade(albedo, normal, alpha, light: Light, gloss=None, view=None, roughness=ROUGHNESS, highlight=HIGHLIGHT,
          sun_visibility=None):
    """Display colour premultiplied by alpha (H, W, 3) in [0, 1]: the sRGB encoding of the straight
    linear colour, times coverage (what an RGBA render composited over black shows)."""
    lin = shade_linear(albedo, normal, light, gloss, view, roughness, highlight, sun_visibility)
    a = alpha[..., None]
    lin.div_(a.clamp_min(1e-6)).masked_fill_(a <= 1e-6, 0.0)  # the straight colour
    return srgb_encode_(lin).mul_(a)


def srgb_encode_(x):
    """srgb_encode in place (x is overwritten and returned)."""
    x.clamp_(0.0, 1.0)
    low = x <= 0.0031308
    lin = x * 12.92
    x.clamp_min_(1e-12).pow_(1 / 2.4).mul_(1.055).sub_(0.055)
    return torch.where(low, lin, x)


def lambert_reference(albedo, normal, light: Light):
    """One surface point, plain numpy: a (E cos / pi + sky) with cos = max(0, n.l) -- the formula
    the tests hold shade_linear to."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    l = np.asarray(light.sun_direction, float) / np.linalg.norm(light.sun_direction)
    return np.asarray(albedo, float) * (max(0.0, float(n @ l)) * light.sun_strength / math.pi
                                        * np.asarray(light.sun_colour, float) + np.asarray(light.sky, float))

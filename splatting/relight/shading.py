"""Per-pixel shading of composited albedo and normal under a sun plus a uniform sky (docs/relighting.md).

Units follow Blender's Cycles so that a light set up here and in Blender renders alike: a sun of
strength E (W/m^2) lights a Lambertian surface of albedo a, normal n with outgoing radiance
a E max(0, n.l) / pi (measured: a 0.5-albedo plane facing a strength-1 sun renders 0.163 in the
Combined pass, 1/pi = 0.318 per unit albedo plus a little specular); a uniform world colour of
radiance L (Blender's background colour x strength) adds a L V_sky whatever the normal, V_sky the
share of the sky the surface sees (1 without a sky visibility: the whole sphere lights it;
shadow.sky_visibility for a bike's self-occlusion).  Shading happens in linear light; the
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


SKY_TINT = (0.92, 0.96, 1.0)  # the sky's colour per unit of strength (grey-blue), random_light's and datasets'


def sun_direction(elevation_deg, azimuth_deg):
    """Towards a sun at this elevation above the ground and azimuth, canonical world frame (Y up;
    azimuth 0 = towards +X, 90 = towards +Z)."""
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return (math.cos(e) * math.cos(a), math.sin(e), math.cos(e) * math.sin(a))


def random_light(rng, min_elevation_deg=15.0, strength=(2.0, 5.0), sky=(0.1, 0.6)):
    """A sun somewhere above the horizon (uniform azimuth, elevation in [min, 90]) with a random warm/cool
    tint and a grey-blue sky; rng: numpy Generator.  What bench/relight.py uses against Blender."""
    az = rng.uniform(0.0, 2 * math.pi)
    el = rng.uniform(min_elevation_deg, 90.0)
    d = sun_direction(el, math.degrees(az))
    tint = rng.uniform(0.85, 1.0, 3)
    s = rng.uniform(*sky)
    return Light(sun_direction=d, sun_colour=tuple(float(x) for x in tint / tint.max()),
                 sun_strength=float(rng.uniform(*strength)), sky=tuple(c * s for c in SKY_TINT))


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


# The shading runs channel-major: (3, P) tensors, one row per component, so the many dot products
# and norms are three row operations each (5x faster than reducing (P, 3) over its last dimension:
# 18 vs 100 us for 22k pixels), which is most of relight_render_overhead.  The public functions
# take and return (..., 3) like the compositor's images.

def _cm(x):
    """(..., 3) -> contiguous (3, P)."""
    return x.reshape(-1, 3).T.contiguous()


def _flat(x):
    return x.reshape(-1) if torch.is_tensor(x) and x.dim() > 0 else x


def _dot(a, b):
    """Row-wise dot product of (3, P) tensors -> (P,)."""
    return (a[0] * b[0]).addcmul_(a[1], b[1]).addcmul_(a[2], b[2])


def _unit(x, eps=1e-6):
    return x / _dot(x, x).sqrt_().clamp_min_(eps)


def _ggx_cm(n, view, l, roughness, cos):
    """ggx_sun for unit (3, P) normals and view directions, l (3,) the sun, cos (P,) n.l."""
    h = view + l[:, None]
    h.div_(_dot(h, h).sqrt_().clamp_min_(1e-6))
    nh = _dot(n, h).clamp_(0.0, 1.0)
    nv = _dot(n, view).clamp_min_(0.05)  # grazing pixels: the lobe's 1/(n.v) would explode
    a2 = roughness ** 4 if torch.is_tensor(roughness) else float(roughness) ** 4  # per pixel or one value
    t = nh.mul_(nh).mul_(a2 - 1.0).add_(1.0)  # n.h^2 (a2 - 1) + 1
    D = t.mul_(t).mul_(4.0 * math.pi).mul_(nv)  # 4 pi t^2 n.v: the denominator of D / (4 n.v)
    D = torch.reciprocal_(D).mul_(a2)
    return D.masked_fill_(cos <= 0, 0.0)


def ggx_sun(normal, view, light: Light, roughness=ROUGHNESS):
    """Sun radiance factor of a glossy surface per unit glossy colour: D_GGX(n.h) / (4 n.v) where
    n.l > 0 (Cook-Torrance with F G folded into the Glossy Color pass, which is the lobe's
    directional albedo).  normal, view: (..., 3) unit, view pointing to the camera."""
    n, l = _cm(normal), light.direction(normal.dtype)
    cos = (n[0] * l[0]).add_(n[1], alpha=float(l[1])).add_(n[2], alpha=float(l[2]))
    return _ggx_cm(n, _cm(view), l, _flat(roughness), cos).reshape(normal.shape[:-1])


def _shade_linear_cm(albedo, normal, light, gloss, view, roughness, highlight, vis, sky_vis=None):
    """shade_linear on (3, P) albedo, normal, gloss, view and (P,) sun and sky visibility -> (3, P)."""
    dt = albedo.dtype
    n = _unit(normal)
    l = light.direction(dt)
    cos = (n[0] * float(l[0])).add_(n[1], alpha=float(l[1])).add_(n[2], alpha=float(l[2])).clamp_min_(0.0)
    sun = (torch.as_tensor(light.sun_colour, dtype=dt) * light.sun_strength)[:, None]
    sky = torch.as_tensor(light.sky, dtype=dt)[:, None]
    if sky_vis is not None:
        sky = sky * sky_vis
    k = cos / math.pi  # the sun's diffuse irradiance / pi
    if vis is not None:
        k.mul_(vis)
    lit = (sun * k).add_(sky)
    if gloss is None:
        return lit.mul_(albedo)
    if view is None:
        return lit.mul_(albedo + gloss)
    spec = _ggx_cm(n, view, l, roughness, cos).mul_(highlight)
    if vis is not None:
        spec.mul_(vis)
    return lit.mul_(albedo).addcmul_((sun * spec).add_(sky), gloss)


def shade_linear(albedo, normal, light: Light, gloss=None, view=None, roughness=ROUGHNESS, highlight=HIGHLIGHT,
                 sun_visibility=None, sky_visibility=None):
    """Premultiplied linear radiance (H, W, 3) of premultiplied albedo and composited normals.

    gloss (premultiplied glossy colour) reflects the sky like the albedo (exact for a uniform sky)
    and the sun as a GGX highlight seen along `view` ((H, W, 3) unit, towards the camera); without
    a view it is shaded like the albedo (the diffuse-like approximation).  sun_visibility (H, W, 1)
    in [0, 1] scales the sun (cast shadows, splatting/relight/shadow.py), sky_visibility (H, W, 1) the
    sky, diffuse and glossy alike (self-occlusion, shadow.sky_visibility); None: unoccluded."""
    out = _shade_linear_cm(_cm(albedo), _cm(normal), light, None if gloss is None else _cm(gloss),
                           None if view is None else _cm(view), _flat(roughness), highlight, _flat(sun_visibility),
                           _flat(sky_visibility))
    return out.T.reshape(albedo.shape)


def _view_directions_cm(camera, rows, cols, dtype=torch.float32):
    """(3, P) unit vectors from the pixels (rows, cols) towards the camera (world frame)."""
    K = camera.K.to(torch.float64)
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    x, y = (cols.to(dtype) + (0.5 - cx)) / fx, (rows.to(dtype) + (0.5 - cy)) / fy
    R = camera.R.to(dtype)
    # the ray R^T (x, y, 1) in the world: x R[0] + y R[1] + R[2], one row per component
    d = R[0][:, None] * x + R[2][:, None]
    d.addcmul_(R[1][:, None], y)
    return d.div_(-_dot(d, d).sqrt_())


def view_directions(camera, dtype=torch.float32, pixels=None):
    """Unit vectors from each pixel's surface towards the camera (world frame): (H, W, 3), or (P, 3)
    for the flat pixel indices `pixels` (P,)."""
    H, W = camera.height, camera.width
    if pixels is None:
        v, u = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
        return _view_directions_cm(camera, v.reshape(-1), u.reshape(-1), dtype).T.reshape(H, W, 3)
    return _view_directions_cm(camera, pixels // W, pixels % W, dtype).T


def _shade_cm(albedo, normal, alpha, light, gloss, view, roughness, highlight, vis, sky_vis=None):
    """shade on (3, P) inputs and (P,) alpha -> (3, P)."""
    lin = _shade_linear_cm(albedo, normal, light, gloss, view, roughness, highlight, vis, sky_vis)
    lin.div_(alpha.clamp_min(1e-6)).masked_fill_(alpha <= 1e-6, 0.0)  # the straight colour
    return srgb_encode_(lin).mul_(alpha)


def shade(albedo, normal, alpha, light: Light, gloss=None, view=None, roughness=ROUGHNESS, highlight=HIGHLIGHT,
          sun_visibility=None, sky_visibility=None):
    """Display colour premultiplied by alpha (H, W, 3) in [0, 1]: the sRGB encoding of the straight
    linear colour, times coverage (what an RGBA render composited over black shows)."""
    out = _shade_cm(_cm(albedo), _cm(normal), alpha.reshape(-1), light, None if gloss is None else _cm(gloss),
                    None if view is None else _cm(view), _flat(roughness), highlight, _flat(sun_visibility),
                    _flat(sky_visibility))
    return out.T.reshape(albedo.shape)


def srgb_encode_(x):
    """srgb_encode in place (x is overwritten by the upper branch; the result is returned)."""
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

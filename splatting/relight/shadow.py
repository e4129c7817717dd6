"""Cast shadows of Gaussians from the sun: a shadow map rendered by the rasterizer's own projection.

The Gaussians are seen from the sun by a far pinhole camera (100 radii away: nearly orthographic)
looking along the light (the rasterizer, so the map costs one more render); per shadow-map pixel,
the first surface is the rasterizer's expected depth where the pixel is mostly covered.  A Gaussian is lit when its centre is no deeper than
that surface plus a bias of a few shadow-map pixels and two of its own sigmas (so a surface made
of stacked, overlapping Gaussians does not shadow itself), read with bilinear weights over the four nearest pixels (soft edges instead of
stair steps).  Per Gaussian, so it is composited like a colour: the pixel's sun term is scaled by
the composited visibility over its coverage.  Cost: one projection + intersection at SIZE px.
"""
import math

import torch

from splatting.raster.camera import Camera
from splatting.raster.api import EPS2D, render_gaussians
from splatting.relight.shading import Light

SIZE = 256        # shadow map pixels (square)
BIAS_PX = 2.0     # lit if no deeper than the first surface + this many map pixels
SIZE_BIAS = 2.0   # + this many of the Gaussian's largest sigma


def sun_camera(means, light, size=SIZE, distance_radii=100.0):
    """A pinhole camera at the sun's side looking along the light, framing all means."""
    l = light.direction(torch.float64)
    m = means.detach().double()
    lo, hi = m.min(0).values, m.max(0).values
    centre, radius = (lo + hi) / 2, float((hi - lo).norm()) / 2 * 1.05 + 1e-6
    z = -l
    up = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
    if abs(float(z @ up)) > 0.99:
        up = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
    x = torch.linalg.cross(up, z)
    x = x / x.norm()
    y = torch.linalg.cross(z, x)
    R = torch.stack([x, y, z])
    C = centre + l * distance_radii * radius
    T = -R @ C
    f = (size / 2) * distance_radii  # radius at distance_radii * radius fills half the map
    K = torch.tensor([[f, 0.0, size / 2], [0.0, f, size / 2], [0.0, 0.0, 1.0]], dtype=torch.float64)
    return Camera(R.float(), T.float(), K.float(), size, size, "sun"), 2 * radius / size


@torch.no_grad()
def sun_visibility(g, light, size=SIZE, bias_px=BIAS_PX, antialiased=False, eps2d=EPS2D):
    """(N,) in [0, 1]: how much of the sun reaches each Gaussian's centre.  antialiased: the mip
    filter in the map (rasterize's bool or (N,) mask) for Gaussians trained with it
    (BikeModel.antialiased): drawn without it, their sub-pixel spokes and cables would grow to
    0.3 px^2 blobs at full opacity and cast more shadow than they have.  eps2d: rasterize's, as g
    was trained (a number or (N,))."""
    cam, px_m = sun_camera(g.means, light, size)
    r = render_gaussians(g, cam, sh_degree=0, antialiased=antialiased, eps2d=eps2d)
    # the first surface: the expected depth of the map pixel (rasterizer's depth / alpha) where it
    # is mostly covered; uncovered pixels light everything behind them
    depth = torch.where(r["alpha"] > 0.5, r["depth"] / r["alpha"].clamp_min(1e-6), torch.full_like(r["alpha"], float("inf")))
    n = len(g)
    pc = g.means.detach().float() @ cam.R.T + cam.T  # the centres in the sun camera
    z = pc[:, 2]
    # bilinear over the 4 nearest map pixels of each centre; outside the map (or no surface): lit
    u = cam.K[0, 0] * pc[:, 0] / z + cam.K[0, 2] - 0.5
    v = cam.K[1, 1] * pc[:, 1] / z + cam.K[1, 2] - 0.5
    u0, v0 = torch.floor(u), torch.floor(v)
    fu, fv = u - u0, v - v0
    vis = torch.zeros(n)
    # a map pixel's depth mixes the centre depths of the Gaussians covering it: on a surface inclined
    # to the sun a neighbour whose footprint covers the pixel sits up to ~2 of its sigmas nearer than
    # the surface point there, so the bias grows with the Gaussian's size (measured: a flat 2 cm-sigma plane lit at
    # 45 degrees came out 13 % lit with the map-pixel bias alone)
    bias = bias_px * px_m + SIZE_BIAS * g.scales.detach().float().max(-1).values
    soft = 0.5 * px_m
    for du, dv, w in ((0, 0, (1 - fu) * (1 - fv)), (1, 0, fu * (1 - fv)), (0, 1, (1 - fu) * fv), (1, 1, fu * fv)):
        ui, vi = (u0 + du).long(), (v0 + dv).long()
        inside = (ui >= 0) & (ui < size) & (vi >= 0) & (vi < size)
        d = torch.full((n,), float("inf"))
        d[inside] = depth[vi[inside], ui[inside]]
        lit = torch.sigmoid(((d + bias - z) / soft).clamp(-30, 30))
        lit = torch.where(torch.isfinite(d), lit, torch.ones_like(lit))
        vis += w * lit
    return vis.clamp(0, 1)


# The sky's occlusion (ambient occlusion) per Gaussian, from shadow maps over the sphere.  Measured
# on the demo's city bike (bench/relight.py poses, 512 px; docs/relighting.md): Blender's own AO
# pass per pixel would take bike_relit 28.31 -> 28.82 dB; this estimate 28.31 -> 28.62 (a constant
# 0.85 for every pixel: 28.49).  32 maps of 256 px with a 3 px bias: 128 px maps or a 2 px bias
# over-darken (median 0.83-0.88 against Blender's 0.91; 28.47-28.56 dB).
SKY_DIRECTIONS = 32
SKY_SIZE = 256
SKY_BIAS_PX = 3.0


def sphere_directions(n):
    """n unit vectors spread evenly over the sphere (Fibonacci lattice), (n, 3) float64."""
    i = torch.arange(n, dtype=torch.float64) + 0.5
    y = 1 - 2 * i / n
    r = (1 - y * y).clamp_min(0).sqrt()
    phi = math.pi * (3 - math.sqrt(5)) * i
    return torch.stack([r * torch.cos(phi), y, r * torch.sin(phi)], -1)


@torch.no_grad()
def sky_visibility(g, normals, directions=SKY_DIRECTIONS, size=SKY_SIZE, bias_px=SKY_BIAS_PX, antialiased=False,
                   eps2d=EPS2D):
    """(N,) in [0, 1]: the share of a uniform sky that reaches each Gaussian, cosine-weighted about
    its normal (what Cycles' AO pass measures): sun_visibility from `directions` directions over
    the sphere, each weighted by max(0, n.d).  normals (N, 3) unit, the frame of g's means.  For a
    uniform sky it depends on the object's shape only, not on where the object is turned, so a
    bike computes it once (RelightableBike.sky_visibility).  antialiased, eps2d: as sun_visibility's."""
    n = normals.float()
    num, den = torch.zeros(len(g)), torch.zeros(len(g))
    for d in sphere_directions(directions):
        w = (n @ d.float()).clamp_min_(0.0)
        num += w * sun_visibility(g, Light(sun_direction=tuple(d.tolist())), size, bias_px, antialiased=antialiased,
                                  eps2d=eps2d)
        den += w
    return (num / den.clamp_min(1e-6)).clamp_(0.0, 1.0)

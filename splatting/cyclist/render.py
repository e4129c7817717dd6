"""Rendering a composed cyclist: RGB, alpha, depth and per-pixel instance ids in one rasterizer pass,
plus projected 2D keypoints with a depth-test visibility.

Instance ids (docs/contract.md: frame 1, steering 2, crank 3, rider 4) are feature channels of the
same rasterization as the RGB image: frame/steering/crank one-hot in three channels; the rider's
share is alpha minus their sum.  A pixel takes the id with the largest composited weight where
alpha > 0.5 (0 = background).
"""

import numpy as np
import torch

from cyclist_formats import instances
from cyclist_formats import ring as formats_ring
from splatting.raster.camera import RING_FOCAL, RING_SIZE, from_numpy
from splatting.raster.api import EPS2D, rasterization

IDS, ID_NAMES = instances.IDS, instances.ID_NAMES
MASK_ALPHA = 0.5


def orbit_camera(azimuth_deg, elevation_deg=0.0, distance=12.0, centre=(0.0, 0.0, 0.0), size=RING_SIZE,
                 focal=None, name=""):
    """The docs/contract.md ring camera generalised by an elevation (degrees, camera above the centre when
    positive).  Azimuth 0, elevation 0 is ring view 0: at centre + (0, 0, -distance), looking along
    +Z, R = diag(-1, -1, 1).  focal defaults to the ring's 2084.97 px scaled to `size`."""
    if focal is None:
        focal = RING_FOCAL * size / RING_SIZE
    R, T, _ = formats_ring.orbit_view(azimuth_deg, elevation_deg, distance, centre)
    return from_numpy(formats_ring.intrinsics(size, focal), R, T, int(size), int(size), name)


@torch.no_grad()
def render_layers(g, ids, camera, antialiased=False, eps2d=EPS2D):
    """Gaussians g (N) with instance ids (N,) int in 1..4 -> dict of float32 numpy arrays:
    rgb (H, W, 3) premultiplied (over black), alpha (H, W), depth (H, W) expected camera z
    (0 where alpha is 0), ids (H, W) uint8.  antialiased: the bike's parts were trained with the
    mip filter (BikeModel.antialiased), so its Gaussians (not the rider's) are drawn with it.
    eps2d: rasterize's, a number or one per Gaussian (compose.frame_eps2d: each model's own)."""
    return render_layers_cameras(g, ids, [camera], antialiased, eps2d)[0]


@torch.no_grad()
def render_layers_cameras(g, ids, cameras, antialiased=False, eps2d=EPS2D):
    """render_layers for several cameras of one size: one rasterization() call, so the views of a
    frame are rendered in one pass of the C++ back end (each view's image the same as alone)."""
    onehot = torch.zeros(len(g), 3)
    bike = ids < IDS["rider"]
    onehot[bike, (ids[bike] - 1).long()] = 1.0
    # one rasterization: the frame/steering/crank one-hot rides along as feature channels (measured
    # 3.6 s -> 0.23 s per 512² frame at 50k Gaussians against compositing the pair list twice)
    outs = rasterization(g.means.float(), g.quats.float(), g.scales.float(), g.opacities.float(), g.sh.float(),
                         cameras=cameras, features=onehot, antialiased=bike & bool(antialiased), eps2d=eps2d,
                         per_camera=True)
    layers = []
    for out in outs:
        rgb, alpha, depth, w3 = out["rgb"], out["alpha"], out["depth"], out["features"]
        weights = torch.cat([w3, (alpha - w3.sum(-1))[..., None]], -1)
        idmap = (weights.argmax(-1) + 1).to(torch.uint8)
        idmap[alpha <= MASK_ALPHA] = 0
        d = torch.where(alpha > 1e-4, depth / alpha.clamp_min(1e-4), torch.zeros_like(depth))
        layers.append({"rgb": rgb.numpy(), "alpha": alpha.numpy(), "depth": d.numpy(), "ids": idmap.numpy()})
    return layers


def project_points(points, camera):
    """(n, 3) world points -> uv (n, 2) pixel coordinates (pixel u covers [u, u+1)), z (n,)."""
    P = torch.as_tensor(np.asarray(points), dtype=torch.float64)
    R, T, K = camera.R.double(), camera.T.double(), camera.K.double()
    x = P @ R.T + T
    z = x[:, 2]
    zs = torch.where(z > 1e-6, z, torch.ones_like(z))
    uv = torch.stack([K[0, 0] * x[:, 0] / zs + K[0, 2], K[1, 1] * x[:, 1] / zs + K[1, 2]], -1)
    return uv.numpy(), z.numpy()


def keypoint_visibility(uv, z, alpha, depth, tolerance_m):
    """COCO visibility per keypoint: 0 outside the image (or behind the camera), 1 inside but
    occluded (the rendered surface at its pixel lies more than tolerance_m in front of it),
    2 visible.  tolerance_m: scalar or (n,) (joints sit inside the body, so they need more)."""
    H, W = alpha.shape
    tol = np.broadcast_to(np.asarray(tolerance_m, dtype=np.float64), (len(z),))
    vis = np.zeros(len(z), dtype=np.int64)
    for i, ((u, v), zi) in enumerate(zip(uv, z)):
        if not (zi > 1e-3 and 0 <= u < W and 0 <= v < H):
            continue
        px, py = int(u), int(v)
        covered = alpha[py, px] > MASK_ALPHA
        vis[i] = 1 if covered and depth[py, px] < zi - tol[i] else 2
    return vis


def to_uint8(x):
    return np.clip(np.asarray(x) * 255.0 + 0.5, 0, 255).astype(np.uint8)


def rgba_image(layers):
    """Straight-alpha RGBA uint8 (H, W, 4) from render_layers output."""
    a = layers["alpha"]
    rgb = layers["rgb"] / np.maximum(a, 1e-6)[..., None]
    rgb[a <= 1e-6] = 0.0
    return np.concatenate([to_uint8(rgb), to_uint8(a)[..., None]], -1)


def over(layers, background):
    """RGB uint8 (H, W, 3): the premultiplied render over a float background (H, W, 3) in [0, 1]."""
    return to_uint8(layers["rgb"] + (1.0 - layers["alpha"])[..., None] * background)

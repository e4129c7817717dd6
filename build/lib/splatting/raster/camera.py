"""Cameras: OpenCV world-to-camera (x_cam = R @ X + T), pinhole K, pixel centres at +0.5.

Torch cameras over cyclist_formats.ring, which owns the ring and cameras.json (docs/contract.md).
"""
from dataclasses import dataclass

import numpy as np
import torch

from cyclist_formats import ring as formats_ring

# the ring of docs/contract.md; cyclist_formats.ring is its one definition
RING_SIZE = formats_ring.SIZE
RING_FOCAL = formats_ring.FOCAL
RING_DISTANCE = formats_ring.DISTANCE


@dataclass
class Camera:
    R: torch.Tensor  # (3, 3) world-to-camera rotation
    T: torch.Tensor  # (3,)   world-to-camera translation
    K: torch.Tensor  # (3, 3) intrinsics, cx = W/2, cy = H/2 for the ring
    width: int
    height: int
    name: str = ""

    @property
    def centre(self):
        """Camera centre in world coordinates: -R^T T."""
        return -self.R.T @ self.T

    def to(self, *args, **kwargs):
        return Camera(self.R.to(*args, **kwargs), self.T.to(*args, **kwargs), self.K.to(*args, **kwargs),
                      self.width, self.height, self.name)

    def scaled(self, factor):
        """The same camera at `factor` times the resolution (coarse-to-fine training)."""
        K = self.K.clone()
        K[:2] *= factor
        return Camera(self.R, self.T, K, int(round(self.width * factor)), int(round(self.height * factor)), self.name)


def from_numpy(K, R, T, width=None, height=None, name="", dtype=torch.float32):
    """A Camera from numpy K, R, T (cyclist_formats.ring); size defaults to 2*cx, 2*cy."""
    K = torch.as_tensor(np.asarray(K, dtype=np.float64))
    w = width or int(round(2 * float(K[0, 2])))
    h = height or int(round(2 * float(K[1, 2])))
    return Camera(torch.as_tensor(np.asarray(R, dtype=np.float64)).to(dtype),
                  torch.as_tensor(np.asarray(T, dtype=np.float64)).to(dtype), K.to(dtype), w, h, name)


def ring_camera(azimuth_deg, orbit_centre=(0.0, 0.0, 0.0), distance=RING_DISTANCE, size=RING_SIZE,
                focal=RING_FOCAL, dtype=torch.float32, name=""):
    """View 0 of the ring (cyclist_formats.ring) turned about +Y through the orbit centre by azimuth_deg."""
    R, T, _ = formats_ring.azimuth_view(azimuth_deg, orbit_centre, distance)
    return from_numpy(formats_ring.intrinsics(size, focal), R, T, size, size, name, dtype)


def ring(n=36, step_deg=10.0, orbit_centre=(0.0, 0.0, 0.0), **kw):
    return [ring_camera(step_deg * i, orbit_centre, name=formats_ring.camera_name(i), **kw) for i in range(n)]


def load_cameras(path, width=None, height=None, dtype=torch.float32):
    """cameras.json -> (list of Camera sorted by name, orbit_centre list or None).

    Image size is not stored in the SHERF layout; it defaults to 2*cx, 2*cy.
    """
    cams, orbit = formats_ring.read_cameras_json(path)
    return [from_numpy(K, R, T, width, height, name, dtype) for name, (K, R, T) in cams.items()], orbit

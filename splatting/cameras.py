"""Cameras: OpenCV world-to-camera (x_cam = R @ X + T), pinhole K, pixel centres at +0.5.

Reads the SHERF/RenderPeople `cameras.json` written by blender_scripts/render_views.py and builds
the 36-view ring of DESIGN.md for views the Blender side never rendered.
"""
import json
import math
from dataclasses import dataclass

import torch

from .errors import UserError

RING_SIZE = 512
RING_FOCAL = 2084.97
RING_DISTANCE = 12.0
R0 = ((-1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 1.0))  # view 0 looks along +Z


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


def ring_camera(azimuth_deg, orbit_centre=(0.0, 0.0, 0.0), distance=RING_DISTANCE, size=RING_SIZE,
                focal=RING_FOCAL, dtype=torch.float32, name=""):
    """View 0 rotated about the vertical (+Y) axis through the orbit centre by azimuth_deg."""
    a = math.radians(azimuth_deg)
    c, s = math.cos(a), math.sin(a)
    Ry = torch.tensor([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]], dtype=torch.float64)
    R = torch.tensor(R0, dtype=torch.float64) @ Ry.T
    centre = torch.tensor(orbit_centre, dtype=torch.float64) + Ry @ torch.tensor([0.0, 0.0, -distance], dtype=torch.float64)
    T = -R @ centre
    K = torch.tensor([[focal, 0.0, size / 2], [0.0, focal, size / 2], [0.0, 0.0, 1.0]], dtype=torch.float64)
    return Camera(R.to(dtype), T.to(dtype), K.to(dtype), size, size, name)


def ring(n=36, step_deg=10.0, orbit_centre=(0.0, 0.0, 0.0), **kw):
    return [ring_camera(step_deg * i, orbit_centre, name=f"camera{i:04d}", **kw) for i in range(n)]


def load_cameras(path, width=None, height=None, dtype=torch.float32):
    """cameras.json -> (list of Camera sorted by name, orbit_centre list or None).

    Image size is not stored in the SHERF layout; it defaults to 2*cx, 2*cy.
    """
    try:
        with open(path) as f:
            data = json.load(f)
    except FileNotFoundError:
        raise UserError(f"no cameras file: {path}")
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise UserError(f"{path} is not valid JSON: {e}")
    except OSError as e:
        raise UserError(f"cannot read {path}: {e.strerror or e}")
    cams = []
    for name in sorted(k for k in data if k.startswith("camera")):
        d = data[name]
        try:
            K = torch.tensor(d["K"], dtype=dtype).reshape(3, 3)
            R = torch.tensor(d["R"], dtype=dtype).reshape(3, 3)
            T = torch.tensor(d["T"], dtype=dtype).reshape(3)
        except (KeyError, RuntimeError, TypeError, ValueError) as e:
            raise UserError(f"{path}: camera {name} needs K (3x3), R (3x3), T (3): {e}")
        w = width or int(round(2 * float(K[0, 2])))
        h = height or int(round(2 * float(K[1, 2])))
        cams.append(Camera(R, T, K, w, h, name))
    if not cams:
        raise UserError(f"{path}: no cameras (expected keys camera0000, camera0001, ...)")
    return cams, data.get("orbit_centre")

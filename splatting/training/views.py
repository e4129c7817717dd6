"""Read one part's views folder (docs/contract.md layout) for training.

    <views>/cameras.json              SHERF: {"camera0000": {"K", "R", "T"}, ..., "orbit_centre": [x, y, z]}
    <views>/rgba/camera%04d/0000.png  straight alpha (preferred)
    <views>/img/camera%04d/0000.jpg + mask/camera%04d/0000.png   fallback (RGB on black + 0/255 mask)
    <views>/transforms.json           NeRF-synthetic, read only when cameras.json is missing
    <views>/points.ply                surface samples, canonical frame (optional; initialises training)

Every problem with the folder is a UserError that names the offending file.
"""
import json
import math
import os
from dataclasses import dataclass

from PIL import Image
import numpy as np
import torch

from splatting.raster.camera import Camera, load_cameras, ring
from cyclist_formats import bike_folder, ply
from cyclist_formats import ring as formats_ring
from cyclist_formats.errors import UserError
from splatting.raster.api import render_gaussians



@dataclass
class Views:
    cameras: list          # Camera per view, sorted by name; width/height = image size
    images: torch.Tensor   # (V, H, W, 4) float32 in [0, 1], straight (non-premultiplied) alpha
    names: list            # "camera0000", ...
    folder: str
    orbit_centre: torch.Tensor = None  # (3,) or None
    points: torch.Tensor = None        # (P, 3) canonical frame, or None
    point_colors: torch.Tensor = None  # (P, 3) in [0, 1], or None

    def __len__(self):
        return len(self.cameras)

    @property
    def height(self):
        return self.images.shape[1]

    @property
    def width(self):
        return self.images.shape[2]

    def subset(self, idx):
        idx = list(idx)
        return Views([self.cameras[i] for i in idx], self.images[idx], [self.names[i] for i in idx], self.folder,
                     self.orbit_centre, self.points, self.point_colors)


def _open_image(path, mode):
    try:
        with Image.open(path) as im:
            im.load()
            if mode == "L" and im.mode not in ("L", "1", "I;16", "I"):
                # A mask saved as RGB(A): any channel set counts (they are equal in a 0/255 mask).
                return np.asarray(im.convert("RGB")).max(-1)
            if mode == "L" and im.mode in ("I;16", "I"):
                a = np.asarray(im).astype(np.float64)
                return (a / max(a.max(), 1.0) * 255).astype(np.uint8)
            return np.asarray(im.convert(mode))
    except FileNotFoundError:
        raise UserError(f"missing image {path}")
    except Exception as e:  # PIL raises many types (UnidentifiedImageError, OSError, SyntaxError)
        raise UserError(f"cannot read image {path}: {e}")


def _load_rgba(folder, name, file_path=None):
    """(H, W, 4) uint8 straight-alpha image for view `name`."""
    if file_path is not None:  # transforms.json gives the path explicitly
        p = os.path.join(folder, file_path)
        cands = [p] if os.path.splitext(p)[1] else [p + ".png", p + ".jpg"]
        for c in cands:
            if os.path.exists(c):
                return _open_image(c, "RGBA")
        raise UserError(f"missing image {cands[0]} (named in transforms.json)")
    paths = bike_folder.view_paths(folder, name)
    rgba, img, mask = paths["rgba"], paths["img"], paths["mask"]
    if os.path.exists(rgba):
        return _open_image(rgba, "RGBA")
    if not os.path.exists(img):
        raise UserError(f"missing image for {name}: neither {rgba} nor {img} exists")
    rgb = _open_image(img, "RGB")
    m = _open_image(mask, "L")
    if m.shape != rgb.shape[:2]:
        raise UserError(f"{mask} is {m.shape[1]}x{m.shape[0]} but {img} is {rgb.shape[1]}x{rgb.shape[0]}")
    # img/ is RGB composited on black with a binary mask: inside the mask it is the straight colour.
    return np.concatenate([rgb, m[..., None]], -1)


def _cameras_from_transforms(path):
    """NeRF-synthetic transforms.json -> [(Camera without size, file_path)].

    NeRF stores camera-to-world in the OpenGL convention (x right, y up, camera looks along -z);
    flipping the y and z camera axes gives OpenCV, whose inverse is our world-to-camera.  The world
    frame is taken as written (docs/contract.md: everything on disk is in the canonical frame).
    """
    try:
        with open(path) as f:
            data = json.load(f)
    except json.JSONDecodeError as e:
        raise UserError(f"{path} is not valid JSON: {e}")
    except (UnicodeDecodeError, OSError) as e:
        raise UserError(f"cannot read {path}: {e}")
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected a JSON object with 'frames'")
    frames = data.get("frames") or []
    if not frames:
        raise UserError(f"{path}: no frames")
    out = []
    for i, fr in enumerate(frames):
        try:
            c2w = torch.tensor(fr["transform_matrix"], dtype=torch.float64).reshape(4, 4)
            fp = fr["file_path"]
        except (KeyError, RuntimeError, TypeError, ValueError) as e:
            raise UserError(f"{path}: frame {i} needs transform_matrix (4x4) and file_path: {e}")
        c2w_cv = c2w[:3, :3] @ torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=torch.float64))
        R = c2w_cv.T
        T = -R @ c2w[:3, 3]
        out.append((R, T, fp, fr))
    return data, out


def _intrinsics(data, fr, w, h, path):
    """K from fl_x/fl_y/cx/cy (per frame or global) or from camera_angle_x (NeRF-synthetic)."""
    get = lambda k: fr.get(k, data.get(k))
    fx, fy = get("fl_x"), get("fl_y")
    if fx is None:
        ax = get("camera_angle_x")
        if ax is None:
            raise UserError(f"{path}: needs camera_angle_x or fl_x")
        fx = 0.5 * w / math.tan(0.5 * float(ax))
    fy = fx if fy is None else fy
    cx = get("cx") if get("cx") is not None else w / 2
    cy = get("cy") if get("cy") is not None else h / 2
    return torch.tensor([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=torch.float64)


def read_points(path):
    """points.ply -> ((P, 3) float32, (P, 3) colours in [0, 1] or None)."""
    xyz, colors = ply.read_points(path)
    return (torch.from_numpy(xyz.astype(np.float32)),
            None if colors is None else torch.from_numpy(colors.astype(np.float32)))


def load_views(folder, dtype=torch.float32) -> Views:
    folder = os.fspath(folder)
    if not os.path.isdir(folder):
        raise UserError(f"views folder not found: {folder}")
    cam_path = os.path.join(folder, "cameras.json")
    tf_path = os.path.join(folder, "transforms.json")
    entries = []  # (name, R, T, K or None, file_path or None)
    orbit = None
    if os.path.exists(cam_path):
        try:
            cams, orbit = load_cameras(cam_path, dtype=torch.float64)
        except UserError as e:
            msg = str(e)
            if "no cameras" in msg:
                raise UserError(f"zero views: {msg}")
            raise
        except (UnicodeDecodeError, OSError, AttributeError) as e:  # binary junk, a directory, a JSON list
            raise UserError(f"cannot read {cam_path}: {e}")
        entries = [(c.name, c.R, c.T, c.K, None) for c in cams]
        tf_data = None
    elif os.path.exists(tf_path):
        tf_data, frames = _cameras_from_transforms(tf_path)
        entries = [(f"camera{i:04d}", R, T, None, fp) for i, (R, T, fp, _) in enumerate(frames)]
    else:
        raise UserError(f"zero views: {folder} has neither cameras.json nor transforms.json")

    images, cameras, names = [], [], []
    for i, (name, R, T, K, fp) in enumerate(entries):
        im = _load_rgba(folder, name, fp)
        h, w = im.shape[:2]
        if images and im.shape != images[0].shape:
            h0, w0 = images[0].shape[:2]
            raise UserError(f"image size mismatch in {folder}: {name} is {w}x{h} but {names[0]} is {w0}x{h0}")
        if K is None:
            K = _intrinsics(tf_data, frames[i][3], w, h, tf_path)
        elif abs(2 * float(K[0, 2]) - w) > 1 or abs(2 * float(K[1, 2]) - h) > 1:
            raise UserError(f"image size mismatch: {name} is {w}x{h} but cameras.json has cx, cy = "
                            f"{float(K[0, 2]):g}, {float(K[1, 2]):g} (expected W/2, H/2)")
        images.append(im)
        names.append(name)
        cameras.append(Camera(R.to(dtype), T.to(dtype), K.to(dtype), w, h, name))
    if not images:
        raise UserError(f"zero views in {folder}")
    imgs = torch.from_numpy(np.stack(images)).to(dtype) / 255.0
    if not (imgs[..., 3] > 0).any():
        raise UserError(f"empty masks: alpha is zero in every view of {folder}")

    points = colors = None
    pts_path = os.path.join(folder, "points.ply")
    if os.path.exists(pts_path):
        points, colors = read_points(pts_path)
        if len(points) == 0:
            points = colors = None
    orbit_t = None if orbit is None else torch.tensor(orbit, dtype=dtype).reshape(3)
    return Views(cameras, imgs, names, folder, orbit_t, points, colors)


def write_views(folder, cameras, images, points=None, orbit_centre=None, point_colors=None):
    """Write a views folder in the docs/contract.md layout (the inverse of load_views; synthetic data, tests).

    cameras: list of Camera (names become the view names); images: (V, H, W, 4) float in [0, 1],
    straight alpha; points: (P, 3) or None.  Writes cameras.json, rgba/, img/ + mask/,
    transforms.json (NeRF-synthetic, camera-to-world in the OpenGL convention) and points.ply.
    """
    os.makedirs(folder, exist_ok=True)
    imgs = (torch.as_tensor(images).clamp(0, 1) * 255).round().to(torch.uint8).numpy()
    cams_json = {}
    for i, cam in enumerate(cameras):
        name = cam.name or formats_ring.camera_name(i)
        cams_json[name] = {"K": cam.K.double().tolist(), "R": cam.R.double().tolist(), "T": cam.T.double().tolist()}
        bike_folder.write_view(folder, name, rgba=imgs[i])
    if orbit_centre is not None:
        cams_json["orbit_centre"] = [float(x) for x in orbit_centre]
    w, h, f = cameras[0].width, cameras[0].height, float(cameras[0].K[0, 0])
    bike_folder.write_views_meta(folder, cams_json, formats_ring.transforms_json(cams_json, w, f, "rgba/{name}/0000.png", h))
    if points is not None:
        rgb = None if point_colors is None else (torch.as_tensor(point_colors).clamp(0, 1) * 255).round().to(torch.uint8).numpy()
        ply.write_points(os.path.join(folder, "points.ply"), torch.as_tensor(points).float().numpy(), rgb=rgb)


def render_ring_views(g, size, orbit_centre):
    """The 36 ring views of Gaussians `g` at `size` px as straight-alpha RGBA (V, H, W, 4), with
    their cameras: synthetic training data in the same form load_views returns."""
    cams = [c.scaled(size / 512) for c in ring(orbit_centre=orbit_centre)]
    imgs = []
    with torch.no_grad():
        for c in cams:
            o = render_gaussians(g, c)
            a = o["alpha"].clamp(0, 1)
            rgb = torch.where(a[..., None] > 0, o["rgb"] / a.clamp_min(1e-8)[..., None], torch.zeros_like(o["rgb"]))
            imgs.append(torch.cat([rgb.clamp(0, 1), a[..., None]], -1))
    return cams, torch.stack(imgs)

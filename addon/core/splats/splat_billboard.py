"""3DGS Gaussians in Blender for one fixed camera, drawn as our rasterizer draws them
(splat_import.py's `camera` mode).

Why, beside the Gaussian mode (splat_gaussian.py, any camera, its rectangles turned to the
camera by Geometry Nodes): here every number is the rasterizer's own, computed in numpy for one
camera (the projected 2D Gaussian with the perspective Jacobian at the FOV-clamped point, the
box, the opacity, the colour), so the Cycles render is the rasterizer's image within 8-bit
rounding, at the price of one import per camera:

- Geometry: each Gaussian becomes a flat quad through its centre, parallel to the image plane
  (instance rotation = the camera's axes, x right, y down, z forward).  A camera ray meets the
  quads in the order of their depth along the optical axis, which is the rasterizer's sort key
  (camera-space z of the centre).  The quad spans the rasterizer's own 3-sigma box around the
  projected centre, cut to the box of the ellipse where alpha reaches 1/255, so Cycles and the
  rasterizer draw the same pixels.
- Opacity (shader): the quad's object coordinates (ox, oy) in [-1, 1]^2 are the pixel offsets
  from the projected centre over the half-widths (ex, ey), exactly (the plane is at constant
  depth z, where a metre is f / z pixels).  alpha = o exp(-0.5 (a ox^2 + 2 b ox oy + c oy^2))
  with (a, b, c) the rasterizer's conic scaled by (ex^2, ex ey, ey^2): the projected covariance
  with the perspective Jacobian (at the FOV-clamped point) plus eps2d px^2, and o times the mip
  filter's compensation where the model was trained antialiased.  Below 1/255 it is 0 and it
  is capped at 0.99, as 3DGS does.
- Colour: the SH evaluated at the direction camera -> centre (as eval_sh), max(0, .), the sRGB
  display value, emitted as is under the Raw view transform (splat_gaussian.DISPLAY_VIEW_TRANSFORM)
  so that Cycles blends display values as the rasterizer does.
- Pixel sampling: the rasterizer evaluates each pixel at its centre; a Gaussian pixel filter
  0.01 px wide (POINT_FILTER) makes every Cycles sample the centre ray, and with Russian roulette off
  (min transparent bounces = max) a render is deterministic: one sample suffices.

The result matches the rasterizer (tests/test_import_splats.py) but only from this camera: the
quads face it, and their alpha and colour were computed for it.  Move the camera and re-import.
"""
import numpy as np

from .. import frames
from .splat_gaussian import ALPHA_MAX, ALPHA_MIN, C0, quat_to_matrix, matrix_to_euler_xyz, sh_degree_of, sh_terms
from .splat_nodes import (emission_over_clear, finish_material, instance_node_group, link_with_nodes, new_material,
                          point_mesh)

EPS2D = 0.3  # the rasterizer's default screen-space low-pass, px^2 (splatting/raster/sparse.py)
NEAR = 0.01  # the rasterizer's near cut, metres
# Cycles' narrowest pixel filter: every sample is the pixel-centre ray, the rasterizer's pixel
# sample.  Gaussian, not Box: Cycles' Box filter is 1 px wide whatever the width says (measured:
# width 3 and 0.01 gave the same image); a Gaussian of width 0.01 samples the centre (10
# overlapping sub-pixel Gaussians at 64 px vs the rasterizer: 52.3 dB with Box, 78.4 dB with it)
POINT_FILTER = ("GAUSSIAN", 0.01)
# a quad per Gaussian along a ray; trained bikes stack a few hundred where a ray crosses a tyre
# lengthwise, and with Russian roulette off every one is walked
TRANSPARENT_BOUNCES = 1024  # also Cycles' largest (its RNA clamps higher values)


def sh_basis(d, degree):
    """Unit directions (N, 3) -> (N, (degree+1)^2) INRIA real SH basis (splatting/gaussians/sh.py)."""
    x, y, z = d.T
    return np.stack(sh_terms(x, y, z, np.full_like(x, C0), degree), 1)


def billboard_points(data, K, R, T, width, height, eps2d=EPS2D, antialiased=False, max_degree=3):
    """Structured 3DGS array + an OpenCV camera (canonical frame; x_cam = R X + T) -> per-quad arrays.

    co (N, 3) Blender frame; rot (N, 3) XYZ Euler of C R^T (the camera's axes); scale (N, 3) =
    (ex z / fx, ey z / fy, 1) with (ex, ey) the quad's half-widths in pixels; conic (N, 3) =
    (A ex^2, B ex ey, C ey^2); opacity (N,); rgb (N, 3) display
    colour; keep (N_file,) the Gaussians drawn (in front of the near plane, projected covariance
    positive definite, box on the image, peak alpha >= 1/255).  The arithmetic follows
    splatting/raster/sparse.py project() and antialias_opacities().
    """
    f = lambda k: data[k].astype(np.float64)  # noqa: E731
    names = data.dtype.names
    K, R, T = (np.asarray(a, np.float64) for a in (K, R, T))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    mu = np.stack([f("x"), f("y"), f("z")], 1)
    p = mu @ R.T + T
    z = p[:, 2]
    valid = z > NEAR
    zs = np.where(valid, z, 1.0)
    x, y = p[:, 0], p[:, 1]
    mx, my = fx * x / zs + cx, fy * y / zs + cy
    limx_pos, limx_neg = (width - cx) / fx + 0.3 * width / (2 * fx), cx / fx + 0.3 * width / (2 * fx)
    limy_pos, limy_neg = (height - cy) / fy + 0.3 * height / (2 * fy), cy / fy + 0.3 * height / (2 * fy)
    tx = np.clip(x / zs, -limx_neg, limx_pos) * zs
    ty = np.clip(y / zs, -limy_neg, limy_pos) * zs
    M = quat_to_matrix(np.stack([f(f"rot_{i}") for i in range(4)], 1)) * np.exp(
        np.stack([f(f"scale_{i}") for i in range(3)], 1))[:, None, :]
    RM = R @ M  # (N, 3, 3): rows r0, r1, r2
    r0, r1, r2 = RM[:, 0], RM[:, 1], RM[:, 2]
    A0 = (fx / zs)[:, None] * r0 - (fx * tx / zs ** 2)[:, None] * r2
    A1 = (fy / zs)[:, None] * r1 - (fy * ty / zs ** 2)[:, None] * r2
    a = (A0 * A0).sum(1) + eps2d
    b = (A0 * A1).sum(1)
    c = (A1 * A1).sum(1) + eps2d
    det = a * c - b * b
    valid &= det > 0
    det_s = np.where(valid, det, 1.0)
    conic = np.stack([c / det_s, -b / det_s, a / det_s], 1)
    op = 1.0 / (1.0 + np.exp(-f("opacity")))
    if antialiased:  # mip filter: o sqrt(det S / det(S + eps2d I))
        op = op * np.sqrt(np.clip(((a - eps2d) * (c - eps2d) - b * b) / det_s, 0.0, None))
    mid = 0.5 * (a + c)
    r = np.ceil(3.0 * np.sqrt(mid + np.sqrt(np.maximum(mid * mid - det, 0.1))))
    # the quad's half-widths: the rasterizer's 3-sigma box, cut to the box of the ellipse where
    # alpha reaches 1/255 (o exp(-q/2) >= 1/255 <=> q <= 2 tau; its half-widths are
    # sqrt(2 tau a), sqrt(2 tau c)).  Outside it alpha is 0 anyway, and faint Gaussians get small
    # quads: fewer transparent hits per ray (Cycles walks at most 1024)
    tau = np.log(np.maximum(255.0 * op, 1.0))
    ex = np.minimum(r, np.sqrt(2.0 * tau * a) + 0.5)
    ey = np.minimum(r, np.sqrt(2.0 * tau * c) + 0.5)
    on_image = (mx + ex > 0.5) & (mx - ex < width - 0.5) & (my + ey > 0.5) & (my - ey < height - 0.5)
    keep = valid & on_image & (op >= ALPHA_MIN)

    deg = min(sh_degree_of(names), max_degree)
    n_rest_file = sum(1 for n in names if n.startswith("f_rest_")) // 3
    basis = sh_basis(_unit(mu - (-R.T @ T)), deg)
    rgb = np.zeros((len(data), 3))
    for c_ in range(3):
        coef = [f(f"f_dc_{c_}")] + [f(f"f_rest_{c_ * n_rest_file + k - 1}") for k in range(1, basis.shape[1])]
        rgb[:, c_] = (basis * np.stack(coef, 1)).sum(1)
    rgb = np.maximum(rgb + 0.5, 0.0)

    Rb = frames.C @ R.T  # quad axes: camera x (right), y (down), z (forward), in Blender's frame
    rot = matrix_to_euler_xyz(Rb[None])[0]
    scale = np.stack([ex * zs / fx, ey * zs / fy, np.ones_like(r)], 1)
    conic = conic * np.stack([ex * ex, ex * ey, ey * ey], 1)  # in the quad's units (Δu/ex, Δv/ey)
    return {"co": frames.to_blender(mu)[keep], "rot": np.tile(rot, (int(keep.sum()), 1)),
            "scale": scale[keep], "conic": conic[keep], "opacity": op[keep],
            "rgb": rgb[keep], "keep": keep, "degree": deg}


def _unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True).clip(1e-30)


# ---- bpy side ----------------------------------------------------------------------------

def billboard_node_group(material, name="splat_camera_quads"):
    """Geometry Nodes: vertices -> points -> a [-1, 1]^2 quad instance per point (g_rot, g_scale)."""
    def quad(n):
        grid = n.new("GeometryNodeMeshGrid")
        grid.inputs["Size X"].default_value = grid.inputs["Size Y"].default_value = 2.0
        grid.inputs["Vertices X"].default_value = grid.inputs["Vertices Y"].default_value = 2
        return grid

    return instance_node_group(name, material, quad)


def billboard_material(name="splat_camera_quad"):
    """Emission of the display colour g_rgb, alpha from the conic g_conic (see the module docstring)."""
    mat, b = new_material(name)
    tex = b.n.new("ShaderNodeTexCoord")
    sep = b.n.new("ShaderNodeSeparateXYZ")
    b.link(tex.outputs["Object"], sep.inputs[0])
    ox, oy = sep.outputs[0], sep.outputs[1]
    con = b.n.new("ShaderNodeSeparateXYZ")
    b.link(b.attr("g_conic"), con.inputs[0])
    q = b.math("ADD", b.math("ADD", b.mul(con.outputs[0], ox, ox), b.mul(con.outputs[1], ox, oy, 2.0)),
               b.mul(con.outputs[2], oy, oy))
    alpha = b.mul(b.attr("opacity", "Fac"), b.math("EXPONENT", b.mul(b.math("MAXIMUM", q, 0.0), -0.5)))
    alpha = b.mul(alpha, b.math("GREATER_THAN", alpha, ALPHA_MIN - 1e-7))  # >= 1/255, as 3DGS
    alpha = b.math("MINIMUM", alpha, ALPHA_MAX)
    return finish_material(mat, b, emission_over_clear(b, b.attr("g_rgb"), alpha), columns=10)


def make_billboard_object(name, pts, material, node_group, collection=None):
    """Vertex-only mesh with opacity, g_rot, g_scale, g_conic, g_rgb attributes and the quad modifier."""
    mesh = point_mesh(name, pts["co"], pts["opacity"], {"g_rot": pts["rot"], "g_scale": pts["scale"],
                                                         "g_conic": pts["conic"], "g_rgb": pts["rgb"]})
    return link_with_nodes(name, mesh, node_group, "splat_camera_quads", collection)

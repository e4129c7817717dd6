"""3DGS Gaussians in Blender as Gaussians, for any camera: a Gaussian falloff and view-dependent
colour from their spherical harmonics (Cycles; splat_import.py's default mode).

Geometry: Geometry Nodes put one rectangle on every Gaussian's centre, in the plane
perpendicular to the line from the camera (the scene's active camera, re-evaluated whenever it
moves), and realize them.  A camera ray therefore meets the Gaussians in the order of their
centres' distances, which along one ray is the rasterizer's order (the centres' depths): the
order 3DGS is trained with.  Closed proxies around each ellipsoid (the earlier import) are met
where the ray enters them, so a large Gaussian inside a tube was composited before the small
ones on its surface (docs/import_splats.md: 5.6 dB behind the rasterizer on the demo bike).
In its plane the rectangle follows the Gaussian's long axis and spans the shadow of its k-sigma
ellipsoid, k = min(K_SIGMA, the radius in sigmas where alpha falls to 1/255), so a ray grazing a
tube meets few empty rectangles (Cycles walks at most 1024 transparent hits).

Opacity (shader): with v the hit's offset from the centre (g_mu) and n the direction camera ->
centre, both in the splat object's coordinates and whitened by the Gaussian's W = S^-1 (C R)^T
(rows g_w0..2; S includes the LOWPASS_M 3D filter below), d^2 = |W v|^2 - (W v . Wn/|Wn|)^2 is
the squared distance, in sigmas, of the line through the hit parallel to n from the centre.
The 3D Gaussian's peak along that line is the rasterizer's projected 2D Gaussian (EWA: the
projection linearised at the centre has its lines of sight parallel to n): alpha = opacity *
exp(-d^2 / 2), times the mip filter's compensation for antialiased models, dropped below 1/255
and capped at 0.99 as 3DGS does.  Cycles composites the hits front to back along each ray.

Colour (shader): colour = max(0, 0.5 + sum_k Y_k(n) sh_k) in the INRIA 3DGS basis and order
(splatting/gaussians/sh.py), as eval_sh; the result is the sRGB display value 3DGS trains
against.  It is emitted as is, and rendered through the Raw view transform, so Cycles
composites display values front to back exactly as the rasterizer does (see
DISPLAY_VIEW_TRANSFORM).  SH coefficient k of a point is the mesh attribute `sh_k` (RGB as a
vector); degrees 0-3 follow the file's f_rest count.
"""
import numpy as np

from .. import frames
from ..contract import sh_basis
from .splat_nodes import (emission_over_clear, enabled_output, finish_material, link_with_nodes, new_material,
                          new_socket, point_mesh)

K_SIGMA = 3.0  # largest proxy extent in standard deviations (3DGS's screen-space cut-off is 3 sigma too)
# The rasterizer adds 0.3 px^2 to every projected covariance (eps2d, 3DGS's low-pass), so the
# trained opacities of sub-pixel Gaussians (spokes, cables) assume that blur.  Drawn in 3D it is
# an isotropic variance of 0.3 (z / f)^2 at the training cameras' distance z and focal f, here
# docs/contract.md's ring (12 m, f = 2084.97 px): sigma = 3.15 mm, added to each Gaussian's covariance
# (the "3D filter" of Mip-Splatting).  Without it thin parts render too faint and too thin.
LOWPASS_M = (0.3 ** 0.5) * 12.0 / 2084.97
ALPHA_MIN, ALPHA_MAX = 1.0 / 255.0, 0.99  # 3DGS's skip threshold and cap
# The rasterizer blends the Gaussians' sRGB display colours (what 3DGS trains against); Cycles
# blends whatever the emission holds.  Emitting the display value and writing it through the Raw
# view transform makes Cycles blend in the same space.  Emitting linear colour under Standard
# (the earlier way) blends in linear light and re-encodes: exact for one Gaussian, but where
# Gaussians overlap the encoding's concave curve brightens the mix (50 % black over white:
# 0.735 instead of 0.5), the speckles on dark tyres and tubes of the trained bike.
DISPLAY_VIEW_TRANSFORM = "Raw"
# the rectangle's half-widths over the k-sigma shadow's: a ray passing within k sigma of the
# centre meets the rectangle (perpendicular to the line of sight through the centre) within the
# shadow / cos of the ray's angle to that line, and that angle is below k max(sigma) / distance
QUAD_MARGIN = 1.02
# INRIA 3DGS real SH, the constants and the numpy basis terms shared with splatting/gaussians/sh.py
C0, C1, C2, C3, sh_terms = sh_basis.C0, sh_basis.C1, sh_basis.C2, sh_basis.C3, sh_basis.sh_terms


# ---- numpy side --------------------------------------------------------------------------

def quat_to_matrix(q):
    """wxyz (N, 4), any norm -> rotation matrices (N, 3, 3)."""
    q = np.asarray(q, float)
    q = q / np.linalg.norm(q, axis=1, keepdims=True).clip(1e-30)
    w, x, y, z = q.T
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                     2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                     2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1).reshape(-1, 3, 3)


def matrix_to_euler_xyz(R):
    """(N, 3, 3) -> Blender 'XYZ' Euler (N, 3) with R = Rz(c) Ry(b) Rx(a)."""
    sy = -R[:, 2, 0]
    b = np.arcsin(np.clip(sy, -1.0, 1.0))
    gimbal = np.abs(sy) > 1 - 1e-9
    a = np.where(gimbal, np.arctan2(-R[:, 1, 2], R[:, 1, 1]), np.arctan2(R[:, 2, 1], R[:, 2, 2]))
    c = np.where(gimbal, 0.0, np.arctan2(R[:, 1, 0], R[:, 0, 0]))
    return np.stack([a, b, c], 1)


def sh_degree_of(names):
    n_rest = sum(1 for n in names if n.startswith("f_rest_"))
    for deg, k in ((3, 45), (2, 24), (1, 9), (0, 0)):
        if n_rest >= k:
            return deg
    return 0


def lowpass_for_view(data, R, T, focal, eps2d):
    """Per-Gaussian 3D low-pass sigma (metres) that draws eps2d px^2 at each Gaussian's depth in
    the camera (x_cam = R X + T, focal in px): sqrt(eps2d) z / f."""
    mu = np.stack([data[k].astype(np.float64) for k in ("x", "y", "z")], 1)
    z = mu @ np.asarray(R, np.float64)[2] + float(np.asarray(T, np.float64)[2])
    return np.sqrt(eps2d) * np.maximum(z, 1e-3) / float(focal)


def gaussian_points(data, max_degree=3, lowpass_m=LOWPASS_M, antialiased=False):
    """Structured 3DGS array -> per-point arrays for the Gaussian mode, Blender frame.

    co (N, 3); opacity (N,) sigmoid; w (N, 3, 3) the whitening W = S^-1 (C R)^T (rows g_w0..2:
    W (p - co) is p's offset from the centre in sigmas, Blender frame); sigma (N, 3) =
    sqrt(exp(log scale)^2 + lowpass_m^2) (lowpass_m a number or (N_file,), lowpass_for_view);
    k (N,) the extent in sigmas, min(K_SIGMA, the radius where alpha falls to 1/255); axes (N, 3,
    3) the k-sigma ellipsoid's semi-axes k sigma_i (C R)_i (g_a0..2); along (N, 3) its long axis
    plus 1e-3 of the middle one (g_along, the rectangle's orientation); mip (N, 3) p_i = the
    product over the other two axes j of sigma0_j^2 / sigma_j^2 (sigma0 without the low-pass;
    ones unless antialiased: gaussian_material's mip filter); Gaussians that never reach
    1/255 are left out (keep (N_file,) says which); sh (N, K, 3) coefficients with sh[:, 0] =
    f_dc and f_rest read channel-major (f_rest_{c * (K-1) + k - 1}); degree.
    """
    f = lambda k: data[k].astype(np.float64)  # noqa: E731
    names = data.dtype.names
    deg = min(sh_degree_of(names), max_degree)
    n_rest_file = sum(1 for n in names if n.startswith("f_rest_")) // 3
    K = (deg + 1) ** 2
    sh = np.zeros((len(data), K, 3))
    sh[:, 0] = np.stack([f(f"f_dc_{c}") for c in range(3)], 1)
    for k in range(1, K):
        for c in range(3):
            sh[:, k, c] = f(f"f_rest_{c * n_rest_file + k - 1}")
    R = quat_to_matrix(np.stack([f(f"rot_{i}") for i in range(4)], 1))
    # the ellipsoid is {C R S u : |u| <= 1} in Blender's frame: its whitening is S^-1 (C R)^T
    Rb = frames.C @ R
    op = 1.0 / (1.0 + np.exp(-f("opacity")))
    keep = op * 255.0 > 1.0
    k = np.sqrt(2.0 * np.log(np.maximum(op * 255.0, 1.0)))  # exp(-k^2/2) op = 1/255
    k = np.minimum(k, K_SIGMA)
    lp = np.asarray(lowpass_m, np.float64).reshape(-1, 1)
    sig = np.sqrt(np.exp(2 * np.stack([f(f"scale_{i}") for i in range(3)], 1)) + lp ** 2)
    w = np.transpose(Rb, (0, 2, 1)) / sig[:, :, None]
    axes = np.transpose(Rb * (k[:, None] * sig)[:, None, :], (0, 2, 1))  # (N, 3 axes, xyz): k sigma_i (C R)_i
    order = np.argsort(-sig, axis=1)
    n = np.arange(len(sig))
    # the rectangle's in-plane x axis follows the long axis; a thousandth of the middle one keeps
    # it defined when the long axis points at the camera
    along = axes[n, order[:, 0]] + 1e-3 * axes[n, order[:, 1]]
    q = np.exp(2 * np.stack([f(f"scale_{i}") for i in range(3)], 1)) / sig ** 2 if antialiased else np.ones_like(sig)
    mip = np.stack([q[:, 1] * q[:, 2], q[:, 0] * q[:, 2], q[:, 0] * q[:, 1]], 1)
    return {"co": frames.to_blender(np.stack([f("x"), f("y"), f("z")], 1))[keep],
            "opacity": op[keep], "w": w[keep], "sigma": sig[keep], "k": k[keep], "axes": axes[keep],
            "along": along[keep], "mip": mip[keep], "sh": sh[keep], "degree": deg, "keep": keep}


# ---- bpy side ----------------------------------------------------------------------------

def gaussian_node_group(material, name="splat_gaussians"):
    """Geometry Nodes: vertices -> points -> a rectangle per point facing the camera, realized.

    Each rectangle ([-1, 1]^2) lies in the plane through the Gaussian's centre perpendicular to
    the line from the camera, so a camera ray meets the rectangles in the order of the centres'
    distances: the rasterizer's order (module docstring).  In that plane its x axis follows the
    long axis (g_along), and its half-widths are the k-sigma ellipsoid's extents along x and y
    (sqrt(sum_i (u . a_i)^2) over the semi-axes g_a0..2), times QUAD_MARGIN: the box of the
    Gaussian's shadow, so a ray grazing a tube meets few empty rectangles (Cycles walks at most
    1024 transparent hits; beyond that a ray turns opaque).  The camera is the scene's active one
    (Active Camera, Blender 4.1+) or the modifier's `Camera` input (3.x); the rectangles turn
    with it whenever it moves.  Realized, so the shader's Object coordinates are the splat
    object's own and the attributes (g_mu, g_w0..2, sh_k) reach the shader as mesh attributes."""
    import bpy

    ng = bpy.data.node_groups.new(name, "GeometryNodeTree")
    new_socket(ng, "Geometry", "INPUT", "NodeSocketGeometry")
    new_socket(ng, "Geometry", "OUTPUT", "NodeSocketGeometry")
    n, link = ng.nodes, ng.links.new
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    if hasattr(bpy.types, "GeometryNodeInputActiveCamera"):
        cam = n.new("GeometryNodeInputActiveCamera").outputs[0]
    else:  # 3.x: the camera object is the modifier's input (set_camera)
        new_socket(ng, "Camera", "INPUT", "NodeSocketObject")
        cam = gin.outputs["Camera"]
    info = n.new("GeometryNodeObjectInfo")
    info.transform_space = "RELATIVE"  # the camera in the splat object's own coordinates
    link(cam, info.inputs["Object"])

    def vmath(op, a, b=None):
        node = n.new("ShaderNodeVectorMath")
        node.operation = op
        for i, x in enumerate((a, b)):
            if x is not None:
                link(x, node.inputs[i])
        return node.outputs["Value" if op in ("DOT_PRODUCT", "LENGTH") else "Vector"]

    def named(attr, kind="FLOAT_VECTOR"):
        a = n.new("GeometryNodeInputNamedAttribute")
        a.data_type = kind
        a.inputs["Name"].default_value = attr
        return enabled_output(a, "Attribute")

    def math(op, a, b=None):
        node = n.new("ShaderNodeMath")
        node.operation = op
        for i, x in enumerate((a, b)):
            if isinstance(x, (int, float)):
                node.inputs[i].default_value = float(x)
            elif x is not None:
                link(x, node.inputs[i])
        return node.outputs[0]

    def extent(u):  # half-width of the k-sigma ellipsoid's shadow along unit u
        sq = [vmath("DOT_PRODUCT", u, named(f"g_a{i}")) for i in range(3)]
        return math("SQRT", math("ADD", math("ADD", math("MULTIPLY", sq[0], sq[0]), math("MULTIPLY", sq[1], sq[1])),
                                 math("MULTIPLY", sq[2], sq[2])))

    to_points = n.new("GeometryNodeMeshToPoints")
    to_points.mode = "VERTICES"
    pos = n.new("GeometryNodeInputPosition")
    towards = vmath("NORMALIZE", vmath("SUBTRACT", info.outputs["Location"], pos.outputs[0]))
    y_axis = vmath("NORMALIZE", vmath("CROSS_PRODUCT", towards, named("g_along")))
    x_axis = vmath("CROSS_PRODUCT", y_axis, towards)
    rotations = "FunctionNodeAlignRotationToVector" if hasattr(bpy.types, "FunctionNodeAlignRotationToVector") \
        else "FunctionNodeAlignEulerToVector"
    face = n.new(rotations)
    face.axis = "Z"
    link(towards, face.inputs["Vector"])
    turn = n.new(rotations)
    turn.axis, turn.pivot_axis = "X", "Z"
    link(face.outputs["Rotation"], turn.inputs["Rotation"])
    link(x_axis, turn.inputs["Vector"])
    size = n.new("ShaderNodeCombineXYZ")
    link(math("MULTIPLY", extent(x_axis), QUAD_MARGIN), size.inputs[0])
    link(math("MULTIPLY", extent(y_axis), QUAD_MARGIN), size.inputs[1])
    size.inputs[2].default_value = 1.0
    grid = n.new("GeometryNodeMeshGrid")
    grid.inputs["Size X"].default_value = grid.inputs["Size Y"].default_value = 2.0
    grid.inputs["Vertices X"].default_value = grid.inputs["Vertices Y"].default_value = 2
    set_mat = n.new("GeometryNodeSetMaterial")
    set_mat.inputs["Material"].default_value = material
    link(grid.outputs["Mesh"], set_mat.inputs["Geometry"])
    inst = n.new("GeometryNodeInstanceOnPoints")
    link(gin.outputs[0], to_points.inputs["Mesh"])
    link(to_points.outputs["Points"], inst.inputs["Points"])
    link(set_mat.outputs["Geometry"], inst.inputs["Instance"])
    link(turn.outputs["Rotation"], inst.inputs["Rotation"])
    link(size.outputs[0], inst.inputs["Scale"])
    realize = n.new("GeometryNodeRealizeInstances")
    link(inst.outputs["Instances"], realize.inputs[0])
    link(realize.outputs[0], gout.inputs[0])
    for i, node in enumerate(n):
        node.location = (200 * (i % 8), -200 * (i // 8))
    return ng


def set_camera(obj, camera):
    """3.x: point the squares of `obj` at `camera` (4.1+ follows the scene's active camera)."""
    mod = obj.modifiers.get("splat_gaussians")
    if mod is None or camera is None:
        return
    ident = next((s.identifier for s in getattr(mod.node_group, "inputs", ()) if s.name == "Camera"), None)
    if ident is not None:
        mod[ident] = camera


def _sh_basis(b, x, y, z, degree):
    """Shader sockets of Y_k(d), k = 1..(degree+1)^2 - 1 (Y_0 = C0 is folded into a constant)."""
    m, s = b.mul, b.math
    out = []
    if degree >= 1:
        out += [m(y, -C1), m(z, C1), m(x, -C1)]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = m(x, x), m(y, y), m(z, z), m(x, y), m(y, z), m(x, z)
        out += [m(xy, C2[0]), m(yz, C2[1]),
                m(s("SUBTRACT", s("SUBTRACT", m(zz, 2.0), xx), yy), C2[2]),
                m(xz, C2[3]), m(s("SUBTRACT", xx, yy), C2[4])]
    if degree >= 3:
        out += [m(y, s("SUBTRACT", m(xx, 3.0), yy), C3[0]),
                m(xy, z, C3[1]),
                m(y, s("SUBTRACT", s("SUBTRACT", m(zz, 4.0), xx), yy), C3[2]),
                m(z, s("SUBTRACT", s("SUBTRACT", m(zz, 2.0), m(xx, 3.0)), m(yy, 3.0)), C3[3]),
                m(x, s("SUBTRACT", s("SUBTRACT", m(zz, 4.0), xx), yy), C3[4]),
                m(z, s("SUBTRACT", xx, yy), C3[5]),
                m(x, s("SUBTRACT", xx, m(yy, 3.0)), C3[6])]
    return out


def gaussian_material(degree, antialiased=False, name="splat_gaussian"):
    """Emission material with the Gaussian falloff and SH colour (see the module docstring);
    antialiased: times the mip filter's opacity compensation (g_mip)."""
    mat, b = new_material(name)
    attr = lambda nm, out="Vector": b.attr(nm, out, "GEOMETRY")  # noqa: E731  (realized squares)
    tex = b.n.new("ShaderNodeTexCoord")
    geo = b.n.new("ShaderNodeNewGeometry")
    # everything in the splat object's coordinates (so moving the object keeps the shading): the
    # hit's offset v from the centre g_mu, and the camera, at the hit + Incoming * (view distance)
    mu = attr("g_mu")
    v = b.vmath("SUBTRACT", tex.outputs["Object"], mu)
    vt = b.n.new("ShaderNodeVectorTransform")
    vt.vector_type, vt.convert_from, vt.convert_to = "VECTOR", "WORLD", "OBJECT"
    b.link(geo.outputs["Incoming"], vt.inputs[0])
    cam_data = b.n.new("ShaderNodeCameraData")
    cam_pos = b.vmath("ADD", tex.outputs["Object"],
                      b.vmath("SCALE", vt.outputs[0], scale=cam_data.outputs["View Distance"]))
    view = b.vmath("SUBTRACT", mu, cam_pos)  # camera -> centre
    # The rasterizer's 2D Gaussian is the 3D one projected by the projection linearised at the
    # centre (EWA), whose lines of sight are all parallel to camera -> centre: the 2D value at a
    # pixel is the 3D Gaussian's peak along the line parallel to `view` through the hit, not along
    # the pixel's own ray (that differs by up to ~0.4 alpha at the edges of Gaussians stretched in
    # depth, seen end-on).  Whitened by the Gaussian's W (rows g_w0..2): sigma units
    rows = [attr(f"g_w{i}") for i in range(3)]
    P, Dw = b.n.new("ShaderNodeCombineXYZ"), b.n.new("ShaderNodeCombineXYZ")
    for i, w in enumerate(rows):
        b.link(b.vmath("DOT_PRODUCT", w, v), P.inputs[i])
        b.link(b.vmath("DOT_PRODUCT", w, view), Dw.inputs[i])
    P = P.outputs[0]
    D = b.vmath("NORMALIZE", Dw.outputs[0])
    t = b.vmath("DOT_PRODUCT", P, D)
    d2 = b.math("SUBTRACT", b.vmath("DOT_PRODUCT", P, P), b.mul(t, t))  # sigma units
    opacity = attr("opacity", "Fac")
    if antialiased:
        # the mip filter: opacity * sqrt(det S / det(S + eps2d I)), S the projected covariance.
        # Projected along the line of sight n, det S is det(Sigma) n^T Sigma^-1 n (up to the
        # focal's square, which cancels), so with Sigma' = Sigma + s^2 I (the low-pass) and
        # m = W n (W whitens Sigma') the ratio is sum_i p_i m_i^2 / |m|^2, p_i the other two
        # axes' product of sigma0^2 / sigma^2 (g_mip, at import)
        m = Dw.outputs[0]
        m2 = b.vmath("MULTIPLY", m, m)
        ratio = b.math("DIVIDE", b.vmath("DOT_PRODUCT", m2, attr("g_mip")), b.vmath("DOT_PRODUCT", m, m))
        opacity = b.mul(opacity, b.math("SQRT", ratio))
    alpha = b.mul(opacity, b.math("EXPONENT", b.mul(b.math("MAXIMUM", d2, 0.0), -0.5)))
    alpha = b.mul(alpha, b.math("GREATER_THAN", alpha, ALPHA_MIN))
    alpha = b.math("MINIMUM", alpha, ALPHA_MAX)

    # SH at the direction camera -> the Gaussian's centre, as the rasterizer's eval_sh; Blender
    # (x, y, z) -> canonical (x, z, -y)
    sep = b.n.new("ShaderNodeSeparateXYZ")
    b.link(b.vmath("NORMALIZE", view), sep.inputs[0])
    x, y, z = sep.outputs[0], sep.outputs[2], b.mul(sep.outputs[1], -1.0)
    col = b.vmath("SCALE", attr("sh_0"), scale=C0)
    for k, Y in enumerate(_sh_basis(b, x, y, z, degree), start=1):
        col = b.vmath("ADD", col, b.vmath("SCALE", attr(f"sh_{k}"), scale=Y))
    col = b.vmath("ADD", col, (0.5, 0.5, 0.5))
    # max(0, .) as the rasterizer's eval_sh; no upper clamp per Gaussian (the rasterizer clamps
    # only the composited pixel, as the PNG does).  The value stays display-referred: it is
    # composited as is and written through the Raw view transform (DISPLAY_VIEW_TRANSFORM)
    col = b.vmath("MAXIMUM", col, (0.0, 0.0, 0.0))

    # one square per Gaussian: no back face to skip
    return finish_material(mat, b, emission_over_clear(b, col, alpha), columns=12)


def make_gaussian_object(name, pts, material, node_group, collection=None):
    """Vertex-only mesh with opacity, g_mu, g_w0..2, g_a0..2, g_along, g_mip, sh_k attributes and the modifier."""
    import bpy

    vectors = {"g_mu": pts["co"], "g_along": pts["along"], "g_mip": pts["mip"], **{f"g_w{i}": pts["w"][:, i] for i in range(3)},
               **{f"g_a{i}": pts["axes"][:, i] for i in range(3)}}
    vectors.update({f"sh_{k}": pts["sh"][:, k] for k in range(pts["sh"].shape[1])})
    mesh = point_mesh(name, pts["co"], pts["opacity"], vectors)
    obj = link_with_nodes(name, mesh, node_group, "splat_gaussians", collection)
    set_camera(obj, bpy.context.scene.camera)
    return obj

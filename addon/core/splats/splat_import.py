"""Import INRIA 3DGS .ply files (docs/contract.md layout) into Blender.

import_splats(mode="gaussian") (the default) draws each Gaussian as a Gaussian, for any camera:
see splat_gaussian.py.  mode="camera" draws them exactly as our rasterizer does, for one camera:
see splat_billboard.py.  This module holds the reader, the dispatch, the sequence keyframing and
the fast "preview" mode; splat_nodes.py the node helpers all three share.

The .ply is read by cyclist_formats.ply (numpy only: Blender 3.4's bundled Python has numpy but
neither plyfile nor torch).

Preview: each .ply becomes a vertex-only mesh (Blender frame, via frames.py) carrying per-point
attributes `opacity`, `radius` and `splat_color` (an attribute named plain `color` rendered black
in Cycles under bpy 5.0), plus a Geometry Nodes modifier (Mesh to Points with the radius
attribute -> Set Material) and an emission material that reads `splat_color` and mixes in a
Transparent BSDF by `opacity`, so Cycles renders each Gaussian as a coloured sphere (a disc
on screen).  A list of files becomes an animated sequence: one object per frame whose
render/viewport visibility is keyframed to that frame only.
"""
import glob
import math
import os

import numpy as np

from .. import frames
from . import splat_billboard as sb, splat_gaussian as sg
from ..contract import UserError, ply
from .splat_nodes import enabled_output, link_with_nodes, new_socket

SH_C0 = 0.28209479177387814  # Y_0^0: 3DGS's colour = 0.5 + C0 * f_dc
# Area-equivalent 1-sigma radius of the Gaussian's two largest axes, times sqrt(2): an opaque
# disc of radius r holds pi*r^2 of "ink" and a 2D Gaussian of peak opacity 1 holds 2*pi*s^2,
# so r = sqrt(2)*s keeps each splat's integrated coverage.  The two largest axes, not the mean
# of three, because trained splats are mostly flat (the third axis would shrink every disc)
# and not the max, which would blow needle-shaped splats up into big balls.
RADIUS_SCALE = math.sqrt(2.0)

REQUIRED = ply.GAUSSIAN_FIELDS


def read_splat_ply(path):
    """A 3DGS .ply -> structured numpy array (N,) with the declared fields (cyclist_formats.ply:
    UserError for a missing file, a non-ply file, missing 3DGS fields, a short body or non-finite
    values)."""
    return ply.read_gaussians(path)


def srgb_to_linear(c):
    """sRGB-encoded [0, 1] -> scene-linear (the IEC 61966-2-1 curve Blender's Standard view inverts)."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def splat_points(data, radius_scale=RADIUS_SCALE):
    """Structured 3DGS array -> per-point arrays in Blender's frame.

    Returns dict: co (N, 3) Blender frame; opacity (N,) = sigmoid(logit); radius (N,) metres;
    color_srgb (N, 3) = clip(0.5 + C0 * f_dc, 0, 1) (the display colour 3DGS trains against);
    color (N, 4) scene-linear RGBA for Blender's FLOAT_COLOR attribute, alpha 1.
    """
    f = lambda k: data[k].astype(np.float64)
    xyz = np.stack([f("x"), f("y"), f("z")], 1)
    dc = np.stack([f(f"f_dc_{c}") for c in range(3)], 1)
    s = np.sort(np.exp(np.stack([f(f"scale_{i}") for i in range(3)], 1)), axis=1)
    srgb = np.clip(0.5 + SH_C0 * dc, 0.0, 1.0)
    color = np.ones((len(data), 4))
    color[:, :3] = srgb_to_linear(srgb)
    return {
        "co": frames.to_blender(xyz),
        "opacity": 1.0 / (1.0 + np.exp(-f("opacity"))),
        "radius": radius_scale * np.sqrt(s[:, 1] * s[:, 2]),
        "color_srgb": srgb,
        "color": color,
    }


def expand_inputs(spec):
    """--ply value -> sorted list of .ply paths: a file, a folder (its *.ply) or a glob."""
    if os.path.isdir(spec):
        paths = sorted(glob.glob(os.path.join(glob.escape(spec), "*.ply")))
        if not paths:
            raise UserError(f"folder {spec} holds no .ply files")
        return paths
    if os.path.isfile(spec):
        return [spec]
    if glob.has_magic(spec):
        paths = sorted(p for p in glob.glob(spec) if os.path.isfile(p))
        if not paths:
            raise UserError(f"no files match {spec}")
        return paths
    raise UserError(f"no such Gaussian file: {spec}")


# ---- bpy side -----------------------------------------------------------------------------

def splat_node_group(material, name="splat_points"):
    """Geometry Nodes: mesh vertices -> points (radius from the `radius` attribute) -> material."""
    import bpy

    ng = bpy.data.node_groups.new(name, "GeometryNodeTree")
    new_socket(ng, "Geometry", "INPUT", "NodeSocketGeometry")
    new_socket(ng, "Geometry", "OUTPUT", "NodeSocketGeometry")
    n = ng.nodes
    gin, gout = n.new("NodeGroupInput"), n.new("NodeGroupOutput")
    radius = n.new("GeometryNodeInputNamedAttribute")
    radius.data_type = "FLOAT"
    radius.inputs["Name"].default_value = "radius"
    to_points = n.new("GeometryNodeMeshToPoints")
    to_points.mode = "VERTICES"
    set_mat = n.new("GeometryNodeSetMaterial")
    set_mat.inputs["Material"].default_value = material
    link = ng.links.new
    link(gin.outputs[0], to_points.inputs["Mesh"])
    link(enabled_output(radius, "Attribute"), to_points.inputs["Radius"])
    link(to_points.outputs["Points"], set_mat.inputs["Geometry"])
    link(set_mat.outputs["Geometry"], gout.inputs[0])
    for i, node in enumerate((gin, radius, to_points, set_mat, gout)):
        node.location = (200 * i, 0)
    return ng


def splat_material(name="splat", shading="emission"):
    """Cycles material reading the `color` and `opacity` point attributes.

    shading="emission" (default) shows the Gaussians' own colour, which already has the
    training lighting baked in; "lit" feeds it to a Principled BSDF as base colour so scene
    lights shade it again.  Alpha is a Transparent BSDF mixed by opacity; back faces are made
    fully transparent so a ray meets each sphere's opacity once, not twice.
    """
    import bpy

    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):  # 5.0 materials always have nodes (use_nodes is deprecated)
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    n, link = nt.nodes, nt.links.new
    col = n.new("ShaderNodeAttribute")
    col.attribute_type = "GEOMETRY"
    col.attribute_name = "splat_color"
    op = n.new("ShaderNodeAttribute")
    op.attribute_type = "GEOMETRY"
    op.attribute_name = "opacity"
    if shading == "emission":
        surf = n.new("ShaderNodeEmission")
        surf.inputs["Strength"].default_value = 1.0
        link(col.outputs["Color"], surf.inputs["Color"])
        surf_out = surf.outputs["Emission"]
    elif shading == "lit":
        surf = n.new("ShaderNodeBsdfPrincipled")
        link(col.outputs["Color"], surf.inputs["Base Color"])
        surf.inputs["Roughness"].default_value = 0.8
        spec = "Specular IOR Level" if "Specular IOR Level" in surf.inputs else "Specular"  # renamed in 4.0
        surf.inputs[spec].default_value = 0.1
        surf_out = surf.outputs["BSDF"]
    else:
        raise UserError(f"unknown shading '{shading}' (emission or lit)")
    clear, clear_back = n.new("ShaderNodeBsdfTransparent"), n.new("ShaderNodeBsdfTransparent")
    alpha = n.new("ShaderNodeMixShader")
    link(op.outputs["Fac"], alpha.inputs["Fac"])
    link(clear.outputs[0], alpha.inputs[1])
    link(surf_out, alpha.inputs[2])
    geo = n.new("ShaderNodeNewGeometry")
    back = n.new("ShaderNodeMixShader")
    link(geo.outputs["Backfacing"], back.inputs["Fac"])
    link(alpha.outputs[0], back.inputs[1])
    link(clear_back.outputs[0], back.inputs[2])
    out = n.new("ShaderNodeOutputMaterial")
    link(back.outputs[0], out.inputs["Surface"])
    for i, node in enumerate((col, surf, alpha, back, out)):
        node.location = (250 * i, 0)
    op.location, clear.location, geo.location, clear_back.location = (250, 250), (250, -250), (500, 250), (500, -250)
    if hasattr(mat, "blend_method"):  # EEVEE viewport only (deprecated from 4.2)
        try:
            mat.blend_method = "BLEND"
        except (AttributeError, TypeError):
            pass
    return mat


def make_point_object(name, pts, material, node_group, collection=None):
    """A vertex-only mesh object with opacity/radius/color attributes and the splat modifier."""
    import bpy

    mesh = bpy.data.meshes.new(name)
    n = len(pts["co"])
    mesh.vertices.add(n)
    mesh.vertices.foreach_set("co", np.ascontiguousarray(pts["co"], dtype=np.float32).ravel())
    for key in ("opacity", "radius"):
        a = mesh.attributes.new(key, "FLOAT", "POINT")
        a.data.foreach_set("value", np.ascontiguousarray(pts[key], dtype=np.float32))
    c = mesh.attributes.new("splat_color", "FLOAT_COLOR", "POINT")
    c.data.foreach_set("color", np.ascontiguousarray(pts["color"], dtype=np.float32).ravel())
    return link_with_nodes(name, mesh, node_group, "splat_points", collection)


def _keyframe_visibility(obj, frame, first, last):
    """Visible (render and viewport) on `frame` only within first..last (bool F-curves step)."""
    keys = [(frame, False)] + [(f, True) for f in (frame - 1, frame + 1) if first <= f <= last]
    for f, hidden in keys:
        obj.hide_render = obj.hide_viewport = hidden
        obj.keyframe_insert("hide_render", frame=f)
        obj.keyframe_insert("hide_viewport", frame=f)


MODES = ("gaussian", "camera", "preview")


def import_splats(paths, shading="emission", radius_scale=RADIUS_SCALE, first_frame=1, mode="gaussian",
                  sh_degree=3, camera=None, eps2d=sb.EPS2D, antialiased=False):
    """Import .ply files into the current scene; several files become frames first_frame, +1, ...

    mode "gaussian" (default): Gaussians (falloff, mip filter, SH colour up to `sh_degree`) on
    rectangles that turn to the scene camera (splat_gaussian.py; emission only), any camera.  mode "camera":
    camera-facing quads that draw exactly what the rasterizer draws, for `camera` only
    (splat_billboard.py).  mode "preview": one sphere per Gaussian (fast; `shading` and
    `radius_scale` apply here).  camera: (K, R, T, width, height), OpenCV world-to-camera in the
    canonical frame; "camera" mode needs it, "gaussian" mode sizes its low-pass for it (eps2d px^2
    at each Gaussian's depth; without it, the training ring's 12 m and 2084.97 px).  eps2d and
    antialiased: the low-pass and mip filter the Gaussians were trained with (both modes draw
    both).  Every file is read and validated before anything is
    created, so bad input leaves the scene untouched.  Returns the list of objects (one per
    file, in frame order).
    """
    import bpy

    if mode not in MODES:
        raise UserError(f"unknown import mode '{mode}' ({' or '.join(MODES)})")
    if not (isinstance(eps2d, (int, float)) and 0 < eps2d < 1e3):
        raise UserError(f"eps2d must be a positive number of px^2, got {eps2d}")
    if isinstance(paths, str):
        paths = [paths]
    scene = bpy.context.scene
    if mode != "preview" and shading != "emission":
        raise UserError("--shading lit goes with --mode preview (Gaussians carry their own lit colour)")
    if mode == "gaussian":
        datas = [read_splat_ply(p) for p in paths]
        lowpass = ([sg.LOWPASS_M * (eps2d / sb.EPS2D) ** 0.5] * len(datas) if camera is None else
                   [sg.lowpass_for_view(d, camera[1], camera[2], camera[0][0, 0], eps2d) for d in datas])
        clouds = [sg.gaussian_points(d, sh_degree, lp, antialiased) for d, lp in zip(datas, lowpass)]
        mat = sg.gaussian_material(max(c["degree"] for c in clouds), antialiased)
        ng = sg.gaussian_node_group(mat)
        make = sg.make_gaussian_object
    elif mode == "camera":
        if camera is None:
            raise UserError("--mode camera draws the Gaussians for one camera: give --camera or --view")
        K, R, T, w, h = camera
        clouds = [sb.billboard_points(read_splat_ply(p), K, R, T, w, h, eps2d, antialiased, sh_degree)
                  for p in paths]
        mat = sb.billboard_material()
        ng = sb.billboard_node_group(mat)
        make = sb.make_billboard_object
    else:
        clouds = [splat_points(read_splat_ply(p), radius_scale) for p in paths]
        mat = splat_material(shading=shading)
        ng = splat_node_group(mat)
        make = make_point_object
    objs = []
    last = first_frame + len(paths) - 1
    for i, (p, pts) in enumerate(zip(paths, clouds)):
        obj = make(os.path.splitext(os.path.basename(p))[0], pts, mat, ng)
        if len(paths) > 1:
            _keyframe_visibility(obj, first_frame + i, first_frame, last)
        objs.append(obj)
    if len(paths) > 1:
        scene.frame_start, scene.frame_end = first_frame, last
        scene.frame_set(first_frame)
    return objs


def data_bbox(paths):
    """Canonical-frame (lo, hi) of the files' Gaussian centres that reach 1/255 opacity (the ones
    every mode draws); read and validated like import_splats."""
    los, his = [], []
    for p in paths:
        d = read_splat_ply(p)
        mu = np.stack([d[k].astype(np.float64) for k in ("x", "y", "z")], 1)
        mu = mu[255.0 / (1.0 + np.exp(-d["opacity"].astype(np.float64))) > 1.0]
        if len(mu):
            los.append(mu.min(0))
            his.append(mu.max(0))
    if not los:
        raise UserError("the Gaussian files hold no Gaussian of opacity >= 1/255")
    return np.min(los, 0), np.max(his, 0)


def points_bbox(objs):
    """Canonical-frame (lo, hi) of the objects' vertices (radius not included)."""
    los, his = [], []
    for o in objs:
        co = np.empty(len(o.data.vertices) * 3, dtype=np.float32)
        o.data.vertices.foreach_get("co", co)
        if len(co):
            M = np.array(o.matrix_world)
            c = frames.to_canonical(co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3])
            los.append(c.min(0))
            his.append(c.max(0))
    if not los:
        raise UserError("the imported point clouds are empty")
    return np.min(los, 0), np.max(his, 0)

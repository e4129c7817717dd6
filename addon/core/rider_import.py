"""Bring a rider mesh (vertex-coloured .ply from splatting.rider.body.export_rider) into Blender
and render it: the 36-view ring of the rest pose (training views for the Gaussian avatar) and
single posed stills (the ground truth the re-posed Gaussians are checked against).

The .ply is parsed here with numpy and built with `from_pydata` + a colour attribute rather than
with Blender's PLY importer, whose operator differs between 3.x (`import_mesh.ply`) and 4.x+
(`wm.ply_import`); this path behaves the same in Blender 3.4 and 5.0.
"""
import math
import os

import bpy
import numpy as np

from . import frames, render
from .script import UserError

RIDER_PASS_INDEX = 4  # DESIGN.md: rider 4 when rendered together with a bike
COLOR_ATTRIBUTE = "Col"

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_colored_ply(path):
    """Binary little-endian triangle .ply -> vertices (V,3) canonical, faces (F,3), colours (V,3)
    sRGB in [0, 1] (white when the file has none)."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except FileNotFoundError:
        raise UserError(f"no rider mesh: {path}")
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply") or end < 0:
        raise UserError(f"{path} is not a .ply file")
    header = data[:end].decode("ascii", "replace").splitlines()
    body = data[end + len(b"end_header\n"):]
    if "format binary_little_endian 1.0" not in header:
        raise UserError(f"{path}: only binary little-endian .ply is supported")
    elements = []  # [name, count, [(prop, dtype)], list spec or None]
    for line in header:
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "element":
            elements.append([tok[1], int(tok[2]), [], None])
        elif tok[0] == "property" and elements:
            if tok[1] == "list":
                elements[-1][3] = (_PLY_TYPES[tok[2]], _PLY_TYPES[tok[3]])
            else:
                elements[-1][2].append((tok[2], "<" + _PLY_TYPES[tok[1]]))
    verts = faces = None
    off = 0
    try:
        for name, count, props, lst in elements:
            if lst is None:
                dt = np.dtype(props)
                arr = np.frombuffer(body, dtype=dt, count=count, offset=off)
                off += dt.itemsize * count
                if name == "vertex":
                    verts = arr
            else:  # assume triangles; checked below
                cnt_t, idx_t = np.dtype("<" + lst[0]), np.dtype("<" + lst[1])
                dt = np.dtype([("n", cnt_t), ("v", idx_t, (3,))])
                arr = np.frombuffer(body, dtype=dt, count=count, offset=off)
                if count and (arr["n"] != 3).any():
                    raise UserError(f"{path}: faces must be triangles")
                off += dt.itemsize * count
                if name == "face":
                    faces = arr["v"].astype(np.int64)
    except ValueError as e:  # buffer shorter than the header promises
        raise UserError(f"{path}: truncated .ply ({e})")
    if verts is None or faces is None:
        raise UserError(f"{path}: needs 'vertex' and 'face' elements")
    v = np.stack([verts[k] for k in ("x", "y", "z")], 1).astype(np.float64)
    if not np.isfinite(v).all():
        raise UserError(f"{path}: non-finite vertex coordinates")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(v)):
        raise UserError(f"{path}: face indices out of range")
    names = verts.dtype.names
    if all(k in names for k in ("red", "green", "blue")):
        c = np.stack([verts[k] for k in ("red", "green", "blue")], 1).astype(np.float64)
        c = c / 255.0 if verts["red"].dtype == np.uint8 else c
    else:
        c = np.ones_like(v)
    return v, faces, c


def srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _vertex_color_material(name):
    """Diffuse BSDF fed by the colour attribute: view-independent, so degree-0 SH can hold it."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):  # 5.0 materials always have nodes (use_nodes is deprecated)
        mat.use_nodes = True
    nt = mat.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfDiffuse")
    col = nt.nodes.new("ShaderNodeVertexColor")  # the "Color Attribute" node
    col.layer_name = COLOR_ATTRIBUTE
    bsdf.inputs["Roughness"].default_value = 1.0
    nt.links.new(col.outputs["Color"], bsdf.inputs["Color"])
    nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return mat


def import_rider(path, name="rider", scene=None):
    """Import a vertex-coloured rider .ply (canonical frame) as one mesh object `name`, pass index 4."""
    scene = scene or bpy.context.scene
    v, f, c = read_colored_ply(path)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(frames.to_blender(v).tolist(), [], f.tolist())
    attr = mesh.color_attributes.new(COLOR_ATTRIBUTE, "FLOAT_COLOR", "POINT")
    rgba = np.concatenate([srgb_to_linear(c), np.ones((len(v), 1))], 1)  # FLOAT_COLOR is scene linear
    attr.data.foreach_set("color", rgba.astype(np.float32).ravel())
    mesh.polygons.foreach_set("use_smooth", np.ones(len(mesh.polygons), dtype=bool))
    mesh.update()
    mesh.materials.append(_vertex_color_material(name + "_vertex_colors"))
    obj = bpy.data.objects.new(name, mesh)
    obj.pass_index = RIDER_PASS_INDEX
    scene.collection.objects.link(obj)
    return obj


def _colored_points_ply(path, v, f, c, n, seed):
    """points.ply for the trainer's initialisation: area-uniform surface samples carrying their
    triangle's mean vertex colour (render_part writes uncoloured ones only when none exist)."""
    pts, nrm, idx = render.sample_surface(v[f], n, seed=seed, return_index=True)
    rgb = np.clip(c[f[idx]].mean(1) * 255 + 0.5, 0, 255).astype(np.uint8)
    render.write_points_ply(path, pts, nrm, rgb)


def render_rider_views(mesh_path, views_dir, views=None, settings=None, n_points=20000, progress=print):
    """The rest-pose rider from the 36-view ring into views_dir (SHERF layout, resumable)."""
    from .scene import reset_scene

    scene = reset_scene()
    s = settings or render.RenderSettings()
    render.configure_cycles(scene, s)
    render.setup_lighting(scene)
    obj = import_rider(mesh_path, scene=scene)
    os.makedirs(views_dir, exist_ok=True)
    ply = os.path.join(views_dir, "points.ply")
    if not os.path.isfile(ply):
        v, f, c = read_colored_ply(mesh_path)
        _colored_points_ply(ply, v, f, c, n_points, s.seed)
    return render.render_part(scene, [obj], views_dir, {}, views=views, settings=s, n_points=n_points,
                              progress=progress, label="rider")


def render_rider_still(mesh_path, camera, out, settings=None, light_yaw_deg=0.0):
    """One posed rider mesh from one camera ('cameras.json:cameraNNNN' or a one-camera JSON).

    light_yaw_deg turns the sun lights about the vertical axis: when the whole body is turned
    by a global yaw, turning the lights with it keeps the shading the avatar was trained under,
    so the comparison measures the skinning rather than relighting. Writes out (RGBA),
    <out>_mask.png and <out>_rgb.jpg like render_pose."""
    from dataclasses import replace

    import mathutils

    from .render_pose import load_camera
    from .scene import reset_scene

    K, R, T = load_camera(camera, os.path.dirname(os.path.abspath(camera.partition(":")[0])))
    size = int(round(2 * K[0, 2]))
    if abs(K[0, 0] - K[1, 1]) > 1e-6 * K[0, 0] or abs(2 * K[1, 2] - size) > 0.5:
        raise UserError("square pixels with the principal point at the image centre only")
    scene = reset_scene()
    s = replace(settings or render.RenderSettings(), size=size)
    render.configure_cycles(scene, s)
    render.setup_lighting(scene)
    if light_yaw_deg:
        a = math.radians(light_yaw_deg)  # about canonical +Y == Blender +Z
        Rz = mathutils.Matrix.Rotation(a, 4, "Z")
        for o in scene.objects:
            if o.type == "LIGHT":
                o.matrix_world = Rz @ o.matrix_world
    obj = import_rider(mesh_path, scene=scene)
    render.show_only(scene, [obj])
    cam = render.ensure_camera(scene, size, K[0, 0])
    render.place_camera(cam, R, T)
    bpy.context.view_layer.update()
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    paths = render.render_atomic(scene, out)
    return paths

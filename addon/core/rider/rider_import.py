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

from .. import frames
from ..render import render
from ..contract import UserError, instances, ply, rider_file

RIDER_PASS_INDEX = instances.RIDER_ID  # docs/contract.md: rider 4 when rendered together with a bike
COLOR_ATTRIBUTE = "Col"

def read_colored_ply(path):
    """Triangle .ply (or an imported rider's rider.npz) -> vertices (V,3) canonical, faces (F,3),
    colours (V,3) sRGB in [0, 1] (white when the file has none)."""
    if not os.path.isfile(path):
        raise UserError(f"no rider mesh: {path}")
    if path.endswith(".npz"):
        a, _ = rider_file.read_rider_file(path)
        return a["vertices"].astype(np.float64), a["faces"].astype(np.int64), a["colors"].astype(np.float64)
    return ply.read_colored_mesh(path)


def _texture_material(name, pixels):
    """Image Texture (the face's UVs) -> Diffuse BSDF, for an imported rider's texture (H,W,3) uint8 sRGB."""
    h, w = pixels.shape[:2]
    img = bpy.data.images.new(name, w, h)  # a byte image: its sRGB values are stored as given
    rgba = np.concatenate([pixels.astype(np.float32) / 255.0, np.ones((h, w, 1), np.float32)], -1)
    img.pixels.foreach_set(rgba.ravel())
    img.pack()  # generated pixels survive a save of the scene
    mat = _vertex_color_material(name)
    nt = mat.node_tree
    col = next(n for n in nt.nodes if n.type == "VERTEX_COLOR")
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Linear"
    bsdf = next(n for n in nt.nodes if n.type == "BSDF_DIFFUSE")
    nt.nodes.remove(col)
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    return mat


def _add_texture_layer(mesh, path, name):
    """An imported rider's texture layer (rider_file uv / face_texture / texture_K): a UV map and one
    material per texture; faces without a texture keep the vertex colours (material 0)."""
    a, _ = rider_file.read_rider_file(path)
    textures = rider_file.textures_of(a)
    if not textures:
        return 0
    layer = mesh.uv_layers.new(name="UVMap")
    layer.data.foreach_set("uv", a["uv"].astype(np.float32).ravel())  # from_pydata: loop 3i+k = corner k of face i
    for k, t in enumerate(textures):
        mesh.materials.append(_texture_material(f"{name}_texture_{k}", t))
    mesh.polygons.foreach_set("material_index", a["face_texture"].astype(np.int32) + 1)
    return len(textures)


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
    """Import a vertex-coloured rider .ply (canonical frame) as one mesh object `name`, pass index 4;
    an imported rider's rider.npz also brings its textures (drawn instead of the vertex colours)."""
    scene = scene or bpy.context.scene
    v, f, c = read_colored_ply(path)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(frames.to_blender(v).tolist(), [], f.tolist())
    attr = mesh.color_attributes.new(COLOR_ATTRIBUTE, "FLOAT_COLOR", "POINT")
    rgba = np.concatenate([srgb_to_linear(c), np.ones((len(v), 1))], 1)  # FLOAT_COLOR is scene linear
    attr.data.foreach_set("color", rgba.astype(np.float32).ravel())
    mesh.polygons.foreach_set("use_smooth", np.ones(len(mesh.polygons), dtype=bool))
    mesh.materials.append(_vertex_color_material(name + "_vertex_colors"))
    if path.endswith(".npz"):
        _add_texture_layer(mesh, path, name)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.pass_index = RIDER_PASS_INDEX
    scene.collection.objects.link(obj)
    return obj


def _colored_points_ply(path, v, f, c, n, seed):
    """points.ply for the trainer's initialisation: area-uniform surface samples carrying their
    triangle's mean vertex colour (render_part writes uncoloured ones only when none exist)."""
    pts, nrm, idx = render.sample_surface(v[f], n, seed=seed, return_index=True)
    rgb = np.clip(c[f[idx]].mean(1) * 255 + 0.5, 0, 255).astype(np.uint8)
    ply.write_points(path, pts, nrm, rgb)


def render_rider_views(mesh_path, views_dir, views=None, settings=None, n_points=20000, progress=print):
    """The rest-pose rider from the 36-view ring into views_dir (SHERF layout, resumable)."""
    from ..scene import reset_scene

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

    from ..render.render_pose import load_camera
    from ..scene import reset_scene

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

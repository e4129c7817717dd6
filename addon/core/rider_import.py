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
from .contract import UserError, instances, ply

RIDER_PASS_INDEX = instances.RIDER_ID  # docs/contract.md: rider 4 when rendered together with a bike
COLOR_ATTRIBUTE = "Col"

def read_colored_ply(path):
    """Triangle .ply -> vertices (V,3) canonical, faces (F,3), colours (V,3) sRGB in [0, 1]
    (white when the file has none)."""
    if not os.path.isfile(path):
        raise UserError(f"no rider mesh: {path}")
    return ply.read_colored_mesh(path)


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
    ply.write_points(path, pts, nrm, rgb)


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

"""Render a bike's parts from the 36-view ring with Cycles on the CPU (bpy).

Per view: one Cycles render to an RGBA PNG; the binary mask (alpha > 0.5) and the RGB-on-black
JPEG are derived from that same render, never from a second one.  Every file is written under
a temporary name and renamed, so a killed run leaves only complete files and a rerun skips the
views that are done.
"""
import math
import os
from dataclasses import dataclass, replace

import bpy
import mathutils
import numpy as np

from .. import frames
from ..contract import bike_folder, instances, ply, ring
from ..contract import atomic, temp_name

PART_IDS = instances.PART_IDS
WHOLE = bike_folder.WHOLE


@dataclass
class RenderSettings:
    """Cycles settings; defaults chosen by `make bench` (see docs/bikes_and_views.md)."""
    samples: int = 16
    adaptive_threshold: float = 0.05
    denoise: str = "FAST"  # "NONE", "FAST", "BALANCED", "HIGH" (OIDN quality; 3.4 ignores quality)
    max_bounces: int = 2
    threads: int = 2
    size: int = ring.SIZE
    seed: int = 0


def configure_cycles(scene, s: RenderSettings):
    scene.render.engine = "CYCLES"
    cy = scene.cycles
    cy.device = "CPU"
    cy.samples = s.samples
    cy.use_adaptive_sampling = s.adaptive_threshold > 0
    if s.adaptive_threshold > 0:
        cy.adaptive_threshold = s.adaptive_threshold
    cy.use_denoising = s.denoise != "NONE"
    if s.denoise != "NONE":
        try:
            cy.denoiser = "OPENIMAGEDENOISE"
        except TypeError:  # Debian's Blender 3.4 is built without OpenImageDenoise
            print("render: OpenImageDenoise is not available in this Blender; rendering without denoising")
            cy.use_denoising = False
            s = replace(s, denoise="NONE")
    if s.denoise != "NONE":
        cy.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        cy.denoising_prefilter = "FAST" if s.denoise == "FAST" else "ACCURATE"
        if hasattr(cy, "denoising_quality"):  # Blender >= 4.1
            cy.denoising_quality = s.denoise
    cy.max_bounces = s.max_bounces
    cy.diffuse_bounces = min(1, s.max_bounces)
    cy.glossy_bounces = min(1, s.max_bounces)
    cy.transmission_bounces = 0
    cy.volume_bounces = 0
    cy.transparent_max_bounces = 2
    cy.caustics_reflective = cy.caustics_refractive = False
    cy.seed = s.seed
    r = scene.render
    r.resolution_x = r.resolution_y = s.size
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.film_transparent = True
    r.use_persistent_data = True  # keep the BVH between the 36 views of one part
    r.threads_mode = "FIXED"
    r.threads = s.threads
    r.image_settings.file_format = "PNG"
    r.image_settings.color_mode = "RGBA"
    r.image_settings.color_depth = "8"
    r.image_settings.compression = 15
    try:
        scene.view_settings.view_transform = "Standard"  # plain sRGB: no Filmic/AgX tone curve
    except TypeError:
        pass
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0


def setup_lighting(scene):
    """Soft, fixed lighting in the canonical world: grey sky + a key sun + a fill sun.

    Lights are fixed in the world (not to the camera) so every view sees the same appearance,
    which is what per-part Gaussians with low SH degree can learn.
    """
    world = bpy.data.worlds.new("studio") if scene.world is None else scene.world
    scene.world = world
    world.use_nodes = True
    bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    bg.inputs["Color"].default_value = (0.8, 0.82, 0.85, 1.0)
    bg.inputs["Strength"].default_value = 0.6
    for name, energy, direction in (("key", 3.0, (0.4, 0.6, 1.0)), ("fill", 1.0, (-0.5, -0.3, 0.8))):
        if name in bpy.data.objects:
            continue
        light = bpy.data.lights.new(name, "SUN")
        light.energy = energy
        light.angle = math.radians(10)
        obj = bpy.data.objects.new(name, light)
        scene.collection.objects.link(obj)
        d = np.asarray(direction, float)  # Blender frame, direction towards the sun
        obj.rotation_mode = "QUATERNION"
        obj.rotation_quaternion = _quat_z_to(d / np.linalg.norm(d))
        # matrix_world too: it stays identity (a sun straight down) until the next depsgraph update,
        # and callers that move the suns with a pose read it before one (bench/render_workers.py did:
        # its 512-spp references were lit from above, not as the training views)
        obj.matrix_world = mathutils.Quaternion(obj.rotation_quaternion).to_matrix().to_4x4()


def _quat_z_to(d):
    """Quaternion (w, x, y, z) turning +Z onto unit vector d (a sun shines along its -Z)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    s = np.linalg.norm(axis)
    if s < 1e-9:
        return (1.0, 0.0, 0.0, 0.0) if d[2] > 0 else (0.0, 1.0, 0.0, 0.0)
    angle = math.atan2(s, float(z @ d))
    axis /= s
    h = angle / 2
    return (math.cos(h), *(math.sin(h) * axis))


def ensure_camera(scene, size=ring.SIZE, focal=ring.FOCAL):
    cam = scene.camera
    if cam is None:
        cam = bpy.data.objects.new("ring_camera", bpy.data.cameras.new("ring_camera"))
        scene.collection.objects.link(cam)
        scene.camera = cam
    cam.data.sensor_fit = "HORIZONTAL"
    cam.data.sensor_width = 36.0
    cam.data.lens = focal * 36.0 / size  # fx = lens / sensor_width * W
    cam.data.shift_x = cam.data.shift_y = 0.0  # cx = W/2, cy = H/2
    cam.data.clip_start = 0.1
    cam.data.clip_end = 1000.0
    return cam


def place_camera(cam, R, T):
    """Put a Blender camera at OpenCV world-to-camera (R, T) given in the canonical frame.

    Blender cameras look along local -Z with +Y up; OpenCV cameras along +Z with +Y down,
    hence the diag(1, -1, -1).  The camera's own axes are local, so only the world side is
    converted (left-multiplication), not conjugated.
    """
    M = ring.camera_to_world_opengl(R, T)
    c4 = np.eye(4)
    c4[:3, :3] = frames.C
    Mb = c4 @ M
    import mathutils
    cam.matrix_world = mathutils.Matrix(Mb.tolist())


def mesh_world_triangles(obj):
    """World-space triangles (T, 3, 3) of an object's evaluated mesh, in the canonical frame."""
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    mesh = ev.to_mesh()
    try:
        mesh.calc_loop_triangles()
        n_v = len(mesh.vertices)
        co = np.empty(n_v * 3)
        mesh.vertices.foreach_get("co", co)
        tris = np.empty(len(mesh.loop_triangles) * 3, dtype=np.int64)
        mesh.loop_triangles.foreach_get("vertices", tris)
    finally:
        ev.to_mesh_clear()
    M = np.array(obj.matrix_world)
    co = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
    return frames.to_canonical(co)[tris.reshape(-1, 3)]


def sample_surface(tris, n, seed=0, return_index=False):
    """Area-weighted uniform samples on triangles -> points (n, 3), normals (n, 3)
    (and the sampled triangle indices (n,) with return_index, e.g. to look up colours)."""
    rng = np.random.default_rng(seed)
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    cr = np.cross(e1, e2)
    area = np.linalg.norm(cr, axis=1)
    idx = rng.choice(len(tris), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = tris[idx, 0] + u[:, None] * e1[idx] + v[:, None] * e2[idx]
    nrm = cr[idx] / np.maximum(area[idx, None], 1e-12)
    return (pts, nrm, idx) if return_index else (pts, nrm)


def render_still(scene, path):
    """One Cycles render written to `path` (PNG, RGBA 8-bit)."""
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    if not os.path.isfile(path):
        raise RuntimeError(f"Blender did not write {path}")


def render_atomic(scene, out, derive=True):
    """Render to a temporary name beside `out`, then rename it there.

    derive=True also writes `<base>_mask.png` and `<base>_rgb.jpg` from the same render.
    Returns the paths written.
    """
    base, _ = os.path.splitext(out)
    paths = {"rgba": out, "img": base + "_rgb.jpg", "mask": base + "_mask.png"} if derive else {"rgba": out}
    tmp = temp_name(out)
    try:
        render_still(scene, tmp)
        if derive:
            bike_folder.write_derived(paths, rendered_png=tmp)
        else:
            os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return paths


def world_bbox(objs):
    pts = []
    for o in objs:
        M = np.array(o.matrix_world)
        c = np.array([list(v) for v in o.bound_box])
        pts.append(c @ M[:3, :3].T + M[:3, 3])
    pts = frames.to_canonical(np.concatenate(pts))
    return pts.min(0), pts.max(0)


def show_only(scene, keep):
    """Hide every mesh but `keep` from the render (lights, camera, armature untouched)."""
    for o in scene.objects:
        if o.type == "MESH":
            o.hide_render = o not in keep


def render_part(scene, part_objs, views_dir, keypoints, views=None, settings=RenderSettings(),
                n_points=20000, progress=print, label="", passes=True):
    """Render one part (or the whole bike) from the ring into views_dir; resumable.

    part_objs: the mesh objects to show; keypoints: {name: canonical xyz} of this part.
    views: indices of the ring to render (default all 36).
    passes: also write the albedo and normal passes of each render (addon/core/render/passes.py).
    """
    from . import passes as render_passes

    if passes:
        render_passes.enable(bpy.context.view_layer)
    os.makedirs(views_dir, exist_ok=True)
    atomic.remove_stale(views_dir)
    show_only(scene, part_objs)
    lo, hi = world_bbox(part_objs)
    orbit = [0.0, float((lo[1] + hi[1]) / 2), 0.0]
    focal = ring.FOCAL * settings.size / ring.SIZE  # a smaller image keeps the same field of view
    cams = ring.ring(orbit, size=settings.size, focal=focal)
    bike_folder.write_views_meta(views_dir, cams, ring.transforms_json(cams, settings.size, focal), keypoints)
    ply_path = os.path.join(views_dir, "points.ply")
    if not os.path.isfile(ply_path):
        tris = np.concatenate([mesh_world_triangles(o) for o in part_objs])
        pts, nrm = sample_surface(tris, n_points, seed=settings.seed)
        ply.write_points(ply_path, pts, nrm)

    cam = ensure_camera(scene, settings.size, focal)
    names = sorted(k for k in cams if k.startswith("camera"))
    todo = [i for i in (range(len(names)) if views is None else views)]
    done = 0
    for n_i, i in enumerate(todo):
        name = names[i]
        paths = bike_folder.view_paths(views_dir, name)
        extra = bike_folder.pass_paths(views_dir, name) if passes else {}
        if bike_folder.view_complete({**paths, **extra}):
            done += 1
            continue
        place_camera(cam, cams[name]["R"], cams[name]["T"])
        tmp = temp_name(paths["rgba"])
        try:
            render_still(scene, tmp)
            if passes:  # before the rgba file, whose presence (with img and mask) marks the view done
                render_passes.write_view_passes(scene, extra)
            bike_folder.write_derived(paths, rendered_png=tmp)  # moves tmp onto the final rgba path, last
        finally:
            if os.path.exists(tmp):
                os.remove(tmp)
        progress(f"{label} view {n_i + 1}/{len(todo)} ({name})")
    return {"views_dir": views_dir, "skipped": done, "rendered": len(todo) - done}

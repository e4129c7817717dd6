"""Test factories that run under bpy or read rendered views, shared by several test modules
(tests never import each other): make_messy writes a messy model file from a procedural bike
(truth kept by material names); check_keypoints_on_masks projects a part's keypoints with its
cameras.json onto its rendered masks."""
import json

import numpy as np
from PIL import Image

from cyclist_formats import ring


def _rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _tris(obj):
    """World-space triangles (k, 3, 3) and the material name of each."""
    me = obj.data
    me.calc_loop_triangles()
    mw = np.array(obj.matrix_world)
    V = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", V)
    V = V.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3]
    T = np.empty(len(me.loop_triangles) * 3, np.int64)
    me.loop_triangles.foreach_get("vertices", T)
    mi = np.empty(len(me.loop_triangles), np.int64)
    me.loop_triangles.foreach_get("material_index", mi)
    names = np.array([(me.materials[i].name if i < len(me.materials) and me.materials[i] else "") for i in range(max(len(me.materials), 1))])
    return V[T.reshape(-1, 3)], names[mi] if len(me.materials) else np.full(len(mi), "")


def _area_centroids(objs):
    """{truth material: (area, area-weighted centroid)} over mesh objects (world frame)."""
    acc = {}
    for o in objs:
        tri, mats = _tris(o)
        a = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        c = tri.mean(1)
        for m in np.unique(mats):
            key = m.split(".")[0]
            sel = mats == m
            A, S = acc.get(key, (0.0, np.zeros(3)))
            acc[key] = (A + a[sel].sum(), S + (c[sel] * a[sel, None]).sum(0))
    return {k: (A, S / A) for k, (A, S) in acc.items() if A > 0}


def make_messy(sp, rng, path, fmt):
    """Write one messy model file; returns the canonical truth centroids per material."""
    import bpy
    from mathutils import Matrix

    from addon.core.frames import to_canonical
    from addon.core.procedural import build
    from addon.core.scene import reset_scene
    reset_scene()
    res = build.build_bike(sp)
    for name, o in res["parts"].items():
        mats = {}
        for k, slot in enumerate(o.material_slots):
            m = bpy.data.materials.new(f"t{name[0]}_{k}")
            m.diffuse_color = tuple(rng.uniform(0, 1, 3)) + (1.0,)
            mats[k] = m
            o.data.materials[k] = m
    for o in list(res["parts"].values()):
        mw = o.matrix_world.copy()
        o.parent = None
        o.matrix_world = mw
    bpy.data.objects.remove(res["armature"], do_unlink=True)
    truth = {k: (A, to_canonical(c)) for k, (A, c) in _area_centroids(res["parts"].values()).items()}
    junk_mat = bpy.data.materials.new("tj_0")
    bpy.ops.mesh.primitive_plane_add(size=float(rng.uniform(3, 8)))
    bpy.context.active_object.data.materials.append(junk_mat)
    d = rng.uniform(1.6, 3.0) * rng.choice([-1, 1])
    bpy.ops.mesh.primitive_cube_add(size=float(rng.uniform(0.1, 0.5)), location=(float(d), float(rng.uniform(-2, 2)), 0.5))
    bpy.context.active_object.data.materials.append(junk_mat)
    bpy.ops.object.camera_add(location=(4.0, -6.0, 2.0))
    bpy.ops.object.light_add(type="POINT", location=(0.0, 0.0, 4.0))
    R = _rotation(rng)
    s = float(10 ** rng.uniform(-2, 2))
    t = rng.normal(size=3) * s
    if rng.random() < 0.5:  # a Y-up model: the bike's up along +Y before the random rotation
        R = R @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T
    Mx = np.eye(4)
    Mx[:3, :3] = s * R
    Mx[:3, 3] = t
    for o in bpy.data.objects:
        o.matrix_world = Matrix(Mx.tolist()) @ o.matrix_world
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    for o in bpy.context.scene.objects:
        o.select_set(o.type == "MESH")
    bpy.context.view_layer.objects.active = meshes[0]
    bpy.ops.object.join()
    bpy.context.active_object.name = "model"
    if fmt == "glb":
        bpy.ops.export_scene.gltf(filepath=str(path))
    else:
        bpy.ops.wm.obj_export(filepath=str(path), up_axis=rng.choice(["Y", "Z"]),
                              forward_axis="NEGATIVE_Z" if rng.random() < 0.5 else "Y")
    return truth


def _mask(views, i):
    return np.asarray(Image.open(views / "mask" / f"camera{i:04d}" / "0000.png"))


def check_keypoints_on_masks(views_dir, indices, tol_px=2):
    cams = json.loads((views_dir / "cameras.json").read_text())
    kps = json.loads((views_dir / "keypoints.json").read_text())["keypoints"]
    assert kps, f"{views_dir} has no keypoints"
    names = list(kps)
    pts = np.array([kps[n] for n in names])
    misses = []
    for i in indices:
        c = cams[f"camera{i:04d}"]
        uv = ring.project(pts, c["K"], c["R"], c["T"])
        m = _mask(views_dir, i) > 0
        ys, xs = np.nonzero(m)
        for n, (u, v) in zip(names, uv):
            # distance from the keypoint's continuous position to the nearest mask pixel centre
            d = np.sqrt((xs + 0.5 - u) ** 2 + (ys + 0.5 - v) ** 2).min() if len(xs) else np.inf
            if d > tol_px:
                misses.append((i, n, round(float(d), 2)))
    assert not misses, f"keypoints off the mask (view, name, px): {misses}"

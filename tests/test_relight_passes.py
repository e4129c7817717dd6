"""The albedo, normal and gloss passes render_part writes beside each view (bpy module, in-process).

A square plane of known colour faces ring view 0: its albedo pass must be that colour and its
normal pass the plane's normal in the canonical frame, in the pixels the mask covers; the EXR
reader must find both passes whichever Blender wrote them.
"""
import math
import os

import numpy as np
import pytest
from PIL import Image

from cyclist_formats import bike_folder

BASE = (0.5, 0.25, 0.1)


@pytest.fixture
def plane_views(fresh_scene, tmp_path):
    import bpy

    from addon.core.render import render

    scene = fresh_scene
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0.0, 0.0, 1.0))
    plane = bpy.context.active_object
    # Blender normal +Z turned by -90 deg about X -> Blender +Y = canonical -Z: it faces ring view 0
    plane.rotation_euler = (-math.pi / 2, 0.0, 0.0)
    mat = bpy.data.materials.new("flat")
    if mat.node_tree is None:
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (*BASE, 1.0)
    bsdf.inputs["Roughness"].default_value = 1.0
    plane.data.materials.append(mat)
    s = render.RenderSettings(samples=1, denoise="NONE", size=32, threads=1)
    render.configure_cycles(scene, s)
    render.setup_lighting(scene)
    views = tmp_path / "views" / "plane"
    render.render_part(scene, [plane], str(views), {}, views=[0, 1, 35], settings=s, n_points=200,
                       progress=lambda *_: None)
    return views


def test_passes_match_the_plane(plane_views):
    for i in (0, 1, 35):
        name = f"camera{i:04d}"
        paths = bike_folder.pass_paths(str(plane_views), name)
        for p in paths.values():
            assert os.path.isfile(p), p
        got = bike_folder.read_passes(paths)
        albedo, normal, gloss = got["albedo"], got["normal"], got["gloss"]
        mask = np.asarray(Image.open(plane_views / "mask" / name / "0000.png")) > 0
        # interior: the mask eroded by one pixel (edge pixels are coverage-weighted)
        inner = mask[1:-1, 1:-1] & mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & mask[1:-1, 2:]
        inner = np.pad(inner, 1)
        assert inner.sum() > 100, "the plane should fill much of the 32 px image"
        # Blender 5.0's Principled BSDF takes ~1.5% of the diffuse for its specular layer
        np.testing.assert_allclose(np.median(albedo[inner], 0), BASE, atol=0.02)
        np.testing.assert_allclose(normal[inner], np.broadcast_to([0.0, 0.0, -1.0], normal[inner].shape), atol=0.02)
        # a non-metallic rough surface: a small grey glossy colour (Fresnel at F0 ~ 0.04..0.08)
        g = np.median(gloss[inner], 0)
        assert np.all(g > 0.01) and np.all(g < 0.2) and np.ptp(g) < 0.01, g
        # outside the object both passes are empty (0 albedo, zero normal)
        out = ~np.pad(mask, 1)[:-2, 1:-1] & ~mask
        assert max(np.abs(x[out]).max() for x in (albedo, normal, gloss)) < 0.01


def test_rerun_skips_complete_views_and_redoes_missing_passes(plane_views, fresh_scene):
    p = bike_folder.pass_paths(str(plane_views), "camera0001")["normal"]
    os.remove(p)
    import bpy

    from addon.core.render import render

    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0.0, 0.0, 1.0))
    s = render.RenderSettings(samples=1, denoise="NONE", size=32, threads=1)
    render.configure_cycles(fresh_scene, s)
    res = render.render_part(fresh_scene, [bpy.context.active_object], str(plane_views), {}, views=[0, 1],
                             settings=s, progress=lambda *_: None)
    assert res["skipped"] == 1 and res["rendered"] == 1
    assert os.path.isfile(p)
    leftovers = [f for f in plane_views.rglob("*") if f.name.startswith(".")]
    assert not leftovers, leftovers  # no temporary (EXR or PNG) stays behind


def test_read_passes_names_a_missing_pass(tmp_path):
    paths = bike_folder.pass_paths(str(tmp_path), "camera0000")
    with pytest.raises(bike_folder.UserError, match="missing albedo pass"):
        bike_folder.read_passes(paths)


def test_pass_encoding_round_trip():
    rng = np.random.default_rng(0)
    alb = rng.random((4, 5, 3))
    n = rng.normal(size=(4, 5, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    enc = bike_folder.encode_passes(alb, n, alb[::-1])
    a8, n8 = enc["albedo"], enc["normal"]
    assert np.array_equal(enc["gloss"], a8[::-1])
    back_a = bike_folder.srgb_decode(a8 / 255.0)
    back_n = n8 / 255.0 * 2 - 1
    assert np.abs(back_n - n).max() < 1.0 / 127.5 + 1e-9
    # 8-bit sRGB: the step is largest at the top of the range, (1 - 254/255 ** 2.4) ~ 0.0094 / 2
    assert np.abs(back_a - alb).max() < 0.005
    # the sRGB curve's known points
    np.testing.assert_allclose(bike_folder.srgb_encode([0.0, 0.0031308, 1.0]), [0.0, 0.04045, 1.0], atol=1e-5)

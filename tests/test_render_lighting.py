"""setup_lighting's suns are placed at once (bpy module, in-process).

Callers that move the suns with a pose (bench/render_workers.py, render_rider_still's light yaw)
read their matrix_world right after setup_lighting, before any depsgraph update: it must already
hold the sun's direction, not the identity (a sun straight down), or those renders are lit
differently from the training views.
"""
import numpy as np


def test_suns_are_placed_before_any_update(fresh_scene):
    import bpy

    from addon.core.render import render

    render.setup_lighting(fresh_scene)
    suns = {o.name: o for o in fresh_scene.objects if o.type == "LIGHT"}
    assert len(suns) == 2, sorted(suns)
    before = {n: np.array(o.matrix_world) for n, o in suns.items()}
    bpy.context.view_layer.update()
    for n, o in suns.items():
        np.testing.assert_allclose(before[n], np.array(o.matrix_world), atol=1e-6, err_msg=n)
        # and not straight down: both suns are set at an angle to the vertical
        assert abs(before[n][2, 2]) < 0.99, n


def test_rider_stills_from_before_the_fix_are_rendered_again(tmp_path):
    # bench/rider.py reuses any gt_NNN.png it finds: stills without the lighting stamp are removed
    # once (and only once), the meshes and cameras beside them are kept
    from bench.rider import STILLS_LIGHTING, forget_stale_stills

    for name in ("gt_000.png", "gt_001.png", "posed_000.ply", "camera_000.json"):
        (tmp_path / name).write_bytes(b"x")
    assert forget_stale_stills(str(tmp_path)) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["camera_000.json", "lighting.json", "posed_000.ply"]
    (tmp_path / "gt_000.png").write_bytes(b"new")  # rendered after the fix
    assert forget_stale_stills(str(tmp_path)) == 0 and (tmp_path / "gt_000.png").read_bytes() == b"new"
    assert STILLS_LIGHTING in (tmp_path / "lighting.json").read_text()

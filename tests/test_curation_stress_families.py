"""Curation under the transformations real files come with (bench/curation_stress.py's failures),
rebuilt from the procedural generator (numpy, no bpy).

Truth comes from the construction: the generator's own keypoints, carried through the same
model-frame transform (tests/test_curation_sides.py's), compared with the curated ones."""
import numpy as np
import pytest

from addon.core.curation import mesh, pipeline

from test_curation_sides import _model, _procedural


def _halved_pedals(V, T, kp):
    """Each pedal body as two separate pieces of equal area, its front half and its back half (a
    rat-trap pedal's two cages, a pedal modelled as two mirrored plates): the triangles of the
    piece holding a pedal keypoint cut at the pedal's middle, the halves 4 cm apart
    along the bike."""
    V, T = V.copy(), T.copy()
    for name in ("pedal_left", "pedal_right"):
        comp = mesh.connected_components(len(V), T)
        area = np.bincount(comp[T[:, 0]], mesh.triangle_areas(V, T), comp.max() + 1)
        near = np.unique(comp[np.linalg.norm(V - kp[name], axis=1) < 0.1])
        c = near[np.argmax(area[near])]          # the pedal body, not its spindle
        tris = np.nonzero(comp[T[:, 0]] == c)[0]
        assert np.ptp(V[np.unique(T[tris])], 0).max() < 0.2, "the pedal body is its own piece"
        is_front = V[T[tris]].mean(1)[:, 0] > kp[name][0]
        for half, dx in ((tris[is_front], 0.02), (tris[~is_front], -0.02)):   # 4 cm apart: never welded
            used = np.unique(T[half])
            remap = np.zeros(len(V), np.int64)
            remap[used] = np.arange(len(V), len(V) + len(used))
            T[half] = remap[T[half]]
            V = np.concatenate([V, V[used] + [dx, 0.0, 0.0]])
    return V, T


@pytest.mark.parametrize("yaw,scale", [(0.0, 1.0), (37.0, 100.0), (143.0, 1.0), (251.0, 1000.0), (90.0, 1.0)])
def test_a_pedal_of_two_equal_pieces_is_found_at_its_middle_whichever_way_the_model_is_turned(yaw, scale):
    """Two pieces of one pedal have the same area up to the file's rounding, so 'the largest
    piece beyond the crank arm' was whichever half the rounding of that rotation favoured (the
    old German roadster: pedal_left 5 cm apart between the file and its Z-up copy).  The pedal
    is both halves: its keypoint at the pedal's middle, the same for every turn and unit."""
    V, T, kp, _ = _procedural(0, 45.0)
    V, T = _halved_pedals(V, T, kp)
    res = pipeline.curate_arrays(_model(V, yaw, scale, False), T, None)
    assert res.problems == [], res.problems

    def where(name):
        return _model(kp[name][None], yaw, scale, False)[0] @ res.M[:3, :3].T + res.M[:3, 3]

    for name in ("pedal_left", "pedal_right"):
        assert np.linalg.norm(res.keypoints[name] - where(name)) < 0.01, (name, res.keypoints[name], where(name))

"""bench/curation_stress.py's comparison: a mirrored variant mapped back, usable vs off vs refused."""
import numpy as np

from bench.curation_stress import _status, keypoint_error, score

BASE = {"pedal_left": [0.1, 0.2, -0.15], "pedal_right": [-0.1, 0.4, 0.15], "front_axle": [0.6, 0.35, 0.0]}


def test_a_mirror_image_is_compared_with_left_and_right_swapped_and_the_side_negated():
    mirrored = {"pedal_right": [0.1, 0.2, 0.15], "pedal_left": [-0.1, 0.4, -0.15], "front_axle": [0.6, 0.35, 0.0]}
    assert keypoint_error(BASE, "mirrored", mirrored) < 1e-12
    assert keypoint_error(BASE, "z_up", mirrored) > 0.2          # not mapped for other variants
    assert keypoint_error(BASE, "z_up", {"front_axle": [0.6, 0.35, 0.0]}) == float("inf")   # a keypoint missing


def test_usable_within_3_cm_off_beyond_and_refusals_and_crashes_apart():
    base = {"keypoints": BASE}
    near = {k: list(np.add(v, [0.0, 0.029, 0.0])) for k, v in BASE.items()}
    far = dict(near, front_axle=[0.65, 0.35, 0.0])
    assert score(base, "glb", {"status": "ok", "keypoints": near})[0] == "usable"
    assert score(base, "glb", {"status": "ok", "keypoints": far})[0] == "off"
    assert score(base, "glb", {"status": "refused", "keypoints": None}) == ("refused", None)
    assert _status(2, "curate.py: error: not a two-wheeler\n") == "refused"
    assert _status(1, "Traceback (most recent call last):\n  ...\nValueError: x\n") == "crash"
    assert _status(0, "") == "ok" and _status(-9, "") == "crash"

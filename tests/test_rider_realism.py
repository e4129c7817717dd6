"""bench/rider_realism.py's scoring (BlazePose itself lives in its own venv and is not run here)."""
import numpy as np

from bench import rider_realism as rr
from bench.frames_realism import COCO_FROM_BLAZE


def _labels():
    k = np.zeros((17, 3))
    k[:, 0] = np.linspace(10, 90, 17)
    k[:, 1] = np.linspace(5, 200, 17)
    k[:, 2] = 2
    k[[5, 6], :2] = [[40, 50], [60, 50]]  # shoulders at y 50, hips at y 150: torso 100 px
    k[[11, 12], :2] = [[42, 150], [58, 150]]
    k[3, 2] = 1  # an occluded ear
    return k


def _blaze_from(k, shift=(0.0, 0.0)):
    p = np.full((33, 2), -1000.0)
    p[list(COCO_FROM_BLAZE)] = k[:, :2] + shift
    return p


def test_pck_counts_points_within_the_torso_fraction():
    k = _labels()
    assert rr.crop_pck(_blaze_from(k), k) == (17, 17)
    assert rr.crop_pck(_blaze_from(k), k, visible_only=True) == (16, 16)
    assert rr.crop_pck(_blaze_from(k, (19.0, 0.0)), k) == (17, 17)  # 0.19 torso
    assert rr.crop_pck(_blaze_from(k, (21.0, 0.0)), k) == (0, 17)  # 0.21 torso
    k2 = k.copy()
    k2[11, 2] = 0  # no torso without both hips labelled
    assert rr.crop_pck(_blaze_from(k2), k2) == (0, 0)


def test_score_per_height():
    k = _labels().tolist()
    rows = [{"file": f"a{h}_{i}.png", "rider": "r1" if i < 2 else "r2", "view": i, "height": h, "box_h": h + 1,
             "keypoints": k} for h in rr.HEIGHTS for i in range(4)]
    good, bad = _blaze_from(_labels()).tolist(), _blaze_from(_labels(), (50.0, 0.0)).tolist()
    poses = {r["file"]: (None if r["view"] == 0 else good if r["rider"] == "r1" else bad) for r in rows}
    s = rr.score(rows, poses)
    for h in rr.HEIGHTS:
        o = s[str(h)]
        assert o["n"] == 4 and o["detected_share"] == 0.75 and o["box_h_median"] == h + 1
        assert o["pck_0.2_torso"] == round(17 / 51, 3)  # one good crop of three detected
        assert o["pck_rider_median"] == 0.5  # r1 1.0, r2 0.0


def test_views_are_the_fixed_four_then_distinct_extra_ones():
    assert rr.views() == rr.VIEWS
    v = rr.views(24)
    assert v[:4] == rr.VIEWS and len(set(v)) == 24
    assert all(0 <= tp < 360 and 0 <= yaw < 360 for tp, yaw in v)

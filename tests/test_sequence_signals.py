"""Arm signals and motion blur in street sequences (issue 29): a signal pose keeps the other hand
on its grip and puts the signalling arm where the codes say; signals are labelled at the frames
before a turn; motion blur is the still image at exposure 0 and differs from it only around a
moving cyclist."""
import json
import math
import os

import numpy as np
import pytest
import torch

from helpers import CITY_KEYPOINTS, street_config
from splatting.dataset.config_models import Sequence


# ---------------------------------------------------------------- the signal poses (IK)

def signal_solve(signals, height=1.75):
    from splatting.bike.pose import posed_bike_keypoints
    from splatting.rider import ik
    from splatting.rider.ik.signals import solve_with_signals
    from splatting.rider.skeleton_template import template_rest_joints
    rest = torch.as_tensor(template_rest_joints(height))
    B = len(signals)
    P = torch.zeros(B, 8, dtype=torch.float64)
    P[:, 0] = torch.linspace(0.0, 330.0, B)  # crank angles through the stroke
    P[:, 1] = torch.linspace(-15.0, 15.0, B)  # steered both ways: the held grip moves with the bars
    kp = {k: torch.as_tensor(np.asarray(v), dtype=torch.float64) for k, v in CITY_KEYPOINTS.items()}
    tg = posed_bike_keypoints(kp, P)
    res = solve_with_signals(rest, tg, signals, ik.DEFAULT_PAIRS, saddle_fit=True, iterations=30)
    return rest, tg, res


def seg(rest, a, b):
    from splatting.rider.kinematics import JOINT_INDEX as J
    return float(torch.linalg.vector_norm(rest[J[b]] - rest[J[a]]))


@pytest.mark.parametrize("signal", ["left", "right", "stop", "one_handed"])
def test_signal_pose_keeps_the_other_hand_on_the_bar(signal):
    from splatting.rider.kinematics import JOINT_INDEX as J
    from splatting.rider.ik.signals import FREE_HAND
    sigs = [signal] * 6
    rest, tg, res = signal_solve(sigs)
    free = FREE_HAND[signal]
    held = "right" if free == "left" else "left"
    # the other hand on its (steered) grip, pelvis on the saddle, feet on the pedals
    for pair in (f"{held}_wrist->handle_{held}", "pelvis->seat", "left_ankle->pedal_left", "right_ankle->pedal_right"):
        assert float(res.residuals[pair].max()) < 0.01, (pair, res.residuals[pair])
        assert not bool(res.free[pair].any())
    assert bool(res.free[f"{free}_wrist->handle_{free}"].all())
    j = res.joints.double()
    sh, el, wr = j[:, J[f"{free}_shoulder"]], j[:, J[f"{free}_elbow"]], j[:, J[f"{free}_wrist"]]
    grip = tg[f"handle_{free}"]
    # the released hand is well away from its grip (the IK reports the distance, unflagged)
    assert float(torch.linalg.vector_norm(wr - grip, dim=-1).min()) > {"stop": 0.3, "one_handed": 0.2}.get(signal, 0.4)
    assert not bool(res.flagged[f"{free}_wrist->handle_{free}"].any())
    l1, l2 = seg(rest, f"{free}_shoulder", f"{free}_elbow"), seg(rest, f"{free}_elbow", f"{free}_wrist")
    out = -1.0 if free == "left" else 1.0  # canonical Z: the rider's right
    if signal in ("left", "right"):
        # arm straight out sideways: the wrist at shoulder height, an arm's length out along +-Z
        assert torch.allclose(wr[:, 1], sh[:, 1], atol=0.02)
        assert torch.allclose(wr[:, 0], sh[:, 0], atol=0.02)
        assert torch.allclose((wr[:, 2] - sh[:, 2]) * out, torch.full((6,), l1 + l2, dtype=torch.float64), atol=0.01)
        assert float((wr[:, 2] - grip[:, 2]).abs().min()) > 0.4  # > 40 cm lateral from its grip
    elif signal == "stop":
        # upper arm out sideways at shoulder height, elbow bent 90 deg, forearm pointing down
        assert torch.allclose(el[:, 1], sh[:, 1], atol=0.02) and bool(((el[:, 2] - sh[:, 2]) * out > l1 - 0.02).all())
        fore = (wr - el) / torch.linalg.vector_norm(wr - el, dim=-1, keepdim=True)
        assert float(torch.rad2deg(torch.acos(-fore[:, 1])).max()) < 5.0
    else:
        assert bool((wr[:, 1] < sh[:, 1] - 0.4).all())  # hanging beside the body
    # the other arm still reaches its grip: steering the bars moves the held hand with them
    assert float(torch.linalg.vector_norm(j[:, J[f"{held}_wrist"]] - tg[f"handle_{held}"], dim=-1).max()) < 0.01


def test_no_signal_is_the_plain_ik_and_mixed_batches_keep_frame_order():
    from splatting.rider import ik
    rest, tg, res = signal_solve(["none", "left", "none", "stop", "right", "none"])
    plain = ik.solve(rest, {k: v[[0, 2, 5]] for k, v in tg.items()}, saddle_fit=True, iterations=30)
    assert torch.equal(res.joints[[0, 2, 5]], plain.joints) and torch.equal(res.local_aa[[0, 2, 5]], plain.local_aa)
    assert [bool(res.free["left_wrist->handle_left"][b]) for b in range(6)] == [False, True, False, True, False, False]
    assert [bool(res.free["right_wrist->handle_right"][b]) for b in range(6)] == [False] * 4 + [True, False]


# ---------------------------------------------------------------- signal timing in sequences

def turn_traj(v=5.0, s0=10.0, fps=10.0, n=60):
    from splatting.dataset.sequences import trajectory as tj
    from splatting.dataset.sequences.trajectory import bike_geometry
    bumps = [tj.turn_bump(s0, -math.pi / 2, 8.0)]
    speed = {"kind": "cruise", "v": v}
    return tj.integrate(n, fps, speed, bumps, bike_geometry(CITY_KEYPOINTS), (0.0, 0.0), 0.0, 2.5, 0.0), speed, bumps


def test_signal_frames_lead_the_turn():
    from splatting.dataset.sequences.draw import signal_frames
    tr, speed, bumps = turn_traj()
    sq = Sequence(signal_share=1.0, signal_lead_s=[1.5, 1.5], one_handed_share=0.0)
    sig = signal_frames(np.random.default_rng(1), "turn_right", tr, speed, bumps, sq, 5.9)
    # the turn starts at s0 = 10 m, t = 2.0 s at 5 m/s: right arm out from 0.5 s until 1.9 s (frames 5..19)
    assert sig == ["none"] * 5 + ["right"] * 15 + ["none"] * 40
    assert np.all(np.abs(tr["kappa"][:20]) < 1e-9) and abs(tr["kappa"][21]) > 1e-4  # the labelled frames precede the turn
    assert signal_frames(np.random.default_rng(1), "turn_right", tr, speed, bumps, sq.model_copy(update={"signal_share": 0.0}), 5.9) == ["none"] * 60
    stop = {"kind": "stop", "v": 5.0, "t0": 3.0, "ramp": 1.5}
    sig = signal_frames(np.random.default_rng(1), "stop", tr, stop, [], sq, 5.9)
    assert sig == ["none"] * 15 + ["stop"] * 15 + ["none"] * 30


def test_one_handed_span_on_straight_rides():
    from splatting.dataset.sequences.draw import signal_frames
    tr, speed, _ = turn_traj()
    sq = Sequence(signal_share=1.0, signal_lead_s=[1.0, 3.0], one_handed_share=1.0)
    for seed in range(5):
        sig = np.array(signal_frames(np.random.default_rng(seed), "straight", tr, speed, [], sq, 5.9))
        on = np.flatnonzero(sig != "none")
        assert set(sig[on]) == {"one_handed"} and np.all(np.diff(on) == 1)
        assert 0.9 <= len(on) / 10.0 <= 4.1  # 1-4 s at 10 fps
    assert set(signal_frames(np.random.default_rng(0), "straight", tr, speed, [], sq.model_copy(update={"one_handed_share": 0.0}), 5.9)) == {"none"}


def test_subframe_poses_follow_the_trajectory(bikes):
    from splatting.dataset.config import validate
    from splatting.dataset.sequences.blur import pose_at
    from splatting.dataset.sequences.draw import draw_sequence
    cfg = validate(street_config(bikes, count=2, sequence={"enabled": True, "length": 30, "fps": 10.0},
                                 street={"cyclists": [3, 3], "parked_bikes": [1, 1], "distance_m": [6, 30]}))
    for s in range(2):
        for inst in draw_sequence(cfg, s)["instances"]:
            for f in (0, 7, 29):  # at a frame's instant: the frame's pose
                p, q = np.array(pose_at(inst, f / 10.0)), inst["poses"][f]
                assert abs(((p[0] - q[0]) + 180) % 360 - 180) < 1e-6 and np.allclose(p[1:], q[1:], atol=1e-6)
            if inst["kind"] == "cyclist":  # between two frames: between their positions
                a, b, m = inst["poses"][10], inst["poses"][11], np.array(pose_at(inst, 1.05))
                assert np.linalg.norm(m[[5, 7]] - 0.5 * (a[[5, 7]] + b[[5, 7]])) < 0.01 + 1e-3 * np.linalg.norm(b[[5, 7]] - a[[5, 7]])


def test_drawn_turns_are_signalled_before_they_start_and_deterministic(bikes):
    from splatting.dataset.config import validate
    from splatting.dataset.sequences.draw import draw_sequence
    only = {m: 0.0 for m in ("straight", "cross", "turn_right", "overtake", "stop", "start", "swerve")}
    cfg = validate(street_config(bikes, count=4, sequence={"enabled": True, "length": 40, "fps": 10.0,
                                                           "manoeuvres": dict(only, turn_left=1.0), "signal_share": 1.0},
                                 street={"cyclists": [3, 3], "parked_bikes": [1, 1], "distance_m": [6, 30]}))
    seen = 0
    for s in range(4):
        sd = draw_sequence(cfg, s)
        assert [i["signal"] for i in draw_sequence(cfg, s)["instances"] if "signal" in i] == \
            [i["signal"] for i in sd["instances"] if "signal" in i]
        for inst in sd["instances"]:
            if inst["kind"] != "cyclist":
                assert "signal" not in inst
                continue
            sig, k, t = np.array(inst["signal"]), inst["traj"]["kappa"], inst["traj"]["t"]
            on = np.flatnonzero(sig != "none")
            assert set(sig[on]) <= {"left"}
            if len(on):
                seen += 1
                assert np.all(np.diff(on) == 1) and np.all(np.abs(k[on]) < 1e-6)  # one span, before the turn
                turning = np.flatnonzero(np.abs(k) > 1e-6)
                assert on[-1] + 1 >= turning[0] - 1  # until the turn starts (the curvature leaves 0 within a frame)
                lo, hi = cfg.sequence.signal_lead_s
                assert t[on[-1]] - t[on[0]] <= hi + 1e-9
    assert seen >= 4
    # with signal_share 0 no cyclist signals, and every other draw is unchanged
    cfg0 = validate(dict(cfg.model_dump(), sequence=dict(cfg.sequence.model_dump(), signal_share=0.0, one_handed_share=0.0)))
    a, b = draw_sequence(cfg, 1), draw_sequence(cfg0, 1)
    assert all(set(i["signal"]) == {"none"} for i in b["instances"] if "signal" in i)
    assert all(np.array_equal(x["poses"], y["poses"]) for x, y in zip(a["instances"], b["instances"]))


@pytest.mark.parametrize("over, field", [({"signal_share": 1.5}, "sequence.signal_share"),
                                         ({"exposure_s": 0.2}, "sequence.exposure_s"),
                                         ({"exposure_s": float("nan")}, "sequence.exposure_s"),
                                         ({"blur_subframes": 4}, "sequence.blur_subframes"),
                                         ({"signal_lead_s": [3, 1]}, "sequence.signal_lead_s")])
def test_bad_signal_and_blur_configs_name_their_field(bikes, over, field):
    from cyclist_formats.errors import UserError
    from splatting.dataset.config import validate
    with pytest.raises(UserError, match=field.replace(".", r"\.")):
        validate(street_config(bikes, sequence=dict({"enabled": True}, **over)))


# ---------------------------------------------------------------- labels in the written formats

def test_signal_labels_in_coco_kitti_and_mot(bikes, tmp_path):
    torch.set_num_threads(1)
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from splatting.dataset.sequences.draw import draw_sequence
    only = {m: 0.0 for m in ("straight", "cross", "turn_right", "overtake", "stop", "start", "swerve")}
    cfg = validate(street_config(bikes, count=1, labels={"formats": ["coco", "kitti", "mot"]},
                                 sequence={"enabled": True, "length": 3, "fps": 10.0, "signal_share": 1.0,
                                           "manoeuvres": dict(only, turn_left=1.0)},
                                 street={"cyclists": [2, 2], "parked_bikes": [0, 0], "distance_m": [6, 12]}))
    out = str(tmp_path / "s")
    generate(cfg, out, log=lambda m: None, progress=False)
    sd = draw_sequence(cfg, 0)
    want = {(f, k + 1): inst["signal"][f] for k, inst in enumerate(sd["instances"]) for f in range(3)}
    assert any(v == "left" for v in want.values())
    with open(os.path.join(out, "annotations.json")) as fh:
        doc = json.load(fh)
    got = {(a["frame_id"], a["track_id"]): a["signal"] for a in doc["annotations"]}
    assert got == want
    assert all(i["signal"] == want[(im["frame_id"], i["track_id"])] for im in doc["images"] for i in im["instances"])
    kit = open(os.path.join(out, "kitti_tracking", "training", "signal_02", "0000.txt")).read().split("\n")[:-1]
    assert {(int(f), int(t)): s for f, t, s in (x.split(" ") for x in kit)} == want
    mot = open(os.path.join(out, "mot", "0000", "gt", "signals.txt")).read().split("\n")[:-1]
    assert {(int(f) - 1, int(t)): s for f, t, s in (x.split(",") for x in mot)} == want


# ---------------------------------------------------------------- motion blur

def blur_config(bikes, **sq):
    only = {m: 0.0 for m in ("cross", "turn_left", "turn_right", "overtake", "stop", "start", "swerve")}
    return street_config(bikes, count=1, sequence=dict({"enabled": True, "length": 3, "fps": 10.0, "speed_mps": [8, 8],
                                                        "manoeuvres": dict(only, straight=1.0), "one_handed_share": 0.0,
                                                        "ego": {"motion": "static", "speed_mps": [0, 0]}}, **sq),
                         street={"cyclists": [1, 1], "parked_bikes": [0, 0], "distance_m": [6, 8], "oncoming_share": 0.0,
                                 "heading": "road", "road_heading_deg": 90.0, "heading_spread_deg": 0.0},
                         appearance={"enabled": False})


def test_blur_at_exposure_zero_is_the_still_image(bikes):
    torch.set_num_threads(1)
    from splatting.dataset.config import validate
    from splatting.dataset.generate import Assets
    from splatting.dataset.sequences.blur import blurred_sample
    from splatting.dataset.sequences.render import drawn, make_frame
    cfg = validate(blur_config(bikes))
    assets = Assets(cfg)
    still = make_frame(cfg, 1, assets)
    rgb, image, anns, _ = blurred_sample(cfg, 1, assets, drawn(cfg, 0, assets), 1, 0.0, 3)
    assert rgb.tobytes() == still[0].tobytes()
    assert [a["bbox"] for a in anns] == [a["bbox"] for a in still[2]]


def test_blur_of_a_moving_cyclist_differs_only_around_it(bikes):
    torch.set_num_threads(1)
    from splatting.dataset.config import validate
    from splatting.dataset.generate import Assets, make_sample
    from splatting.dataset.sequences.blur import subframe_draw, subframe_offsets
    from splatting.dataset.sequences.draw import ego_camera
    from splatting.dataset.sequences.render import drawn, make_frame
    cfg = validate(blur_config(bikes))
    cfg_b = validate(blur_config(bikes, exposure_s=0.05, blur_subframes=5))
    assets = Assets(cfg)
    still = make_frame(cfg, 1, assets)
    blurred = make_frame(cfg_b, 1, Assets(cfg_b))
    # the labels are those of the frame's (mid-exposure) instant
    assert json.dumps(blurred[2]) == json.dumps(still[2])
    diff = np.abs(blurred[0].astype(int) - still[0].astype(int)).max(2) > 1
    assert diff.sum() > 50  # an 8 m/s cyclist moves ~40 cm in the exposure: its edges smear
    # every changed pixel lies within the union of the cyclist's boxes over the exposure
    sd = drawn(cfg, 0, assets)
    ys, xs = np.nonzero(diff)
    box = [np.inf, np.inf, -np.inf, -np.inf]
    for dt in subframe_offsets(0.05, 5)[[0, -1]]:
        anns = make_sample(cfg, 1, assets, drawn=subframe_draw(sd, 1, 0.1 + dt), camera=ego_camera(sd, 1), look_index=0)[2]
        for a in anns:
            x, y, w, h = a["bbox_amodal"]
            box = [min(box[0], x), min(box[1], y), max(box[2], x + w), max(box[3], y + h)]
    assert xs.min() >= box[0] - 2 and xs.max() <= box[2] + 2 and ys.min() >= box[1] - 2 and ys.max() <= box[3] + 2


# ---------------------------------------------------------------- still datasets

def test_still_signals_optional_and_default_off(bikes):
    torch.set_num_threads(1)
    from helpers import small_config
    from splatting.dataset.config import validate
    from splatting.dataset.generate import Assets, draw, make_sample
    cfg = validate(small_config(bikes, count=4))
    assert all("signal" not in i for n in range(4) for i in draw(cfg, n)["instances"])
    cfg1 = validate(small_config(bikes, count=4, sequence={"still_signal_share": 1.0}))
    d0, d1 = draw(cfg, 2), draw(cfg1, 2)
    assert [i["pose"] for i in d0["instances"]] == [i["pose"] for i in d1["instances"]]  # other draws unchanged
    sig = [i["signal"] for n in range(4) for i in draw(cfg1, n)["instances"]]
    assert set(sig) <= {"left", "right", "stop", "one_handed"} and len(set(sig)) >= 2
    rgb, image, anns, _ = make_sample(cfg1, 2, Assets(cfg1))
    assert image["ik"]["signal"] == d1["instances"][0]["signal"] and all(a["signal"] == image["ik"]["signal"] for a in anns)
    assert len(image["ik"]["residual_m"]) == 4  # the released hand's pair is left out
    rgb0, image0, anns0, _ = make_sample(cfg, 2, Assets(cfg))
    assert "signal" not in image0["instances"][0] and all("signal" not in a for a in anns0)
    assert rgb.tobytes() != rgb0.tobytes()  # the arm moved


def test_unknown_signal_is_a_user_error():
    from cyclist_formats.errors import UserError
    with pytest.raises(UserError, match="wave"):
        signal_solve(["none", "wave"])

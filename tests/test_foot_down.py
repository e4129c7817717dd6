"""A foot on the ground at a stop (splatting/rider/ik/foot_down.py): the grounded ankle reaches
the road beside the leaning bike, the other foot stays on its pedal, both hands on the grips and
the pelvis on the saddle; no foot down is the ordinary IK."""
import math

import numpy as np
import pytest
import torch

from helpers import CITY_KEYPOINTS


def _solve(feet, height=1.80, crank=0.0):
    from splatting.bike.pose import posed_bike_keypoints
    from splatting.rider import ik
    from splatting.rider.ik.foot_down import lean_deg, solve_with_feet
    from splatting.rider.skeleton_template import template_rest_joints

    rest = torch.as_tensor(template_rest_joints(height))
    B = len(feet)
    P = torch.zeros(B, 8, dtype=torch.float64)
    P[:, 0] = crank
    kp = {k: torch.as_tensor(np.asarray(v), dtype=torch.float64) for k, v in CITY_KEYPOINTS.items()}
    tg = posed_bike_keypoints(kp, P)
    lean = [lean_deg(f) for f in feet]
    res = solve_with_feet(rest, tg, feet, ik.DEFAULT_PAIRS, kp["crank_axle"].numpy(), lean, saddle_fit=True, iterations=40)
    return tg, lean, res


@pytest.mark.parametrize("foot", ["left", "right"])
def test_grounded_foot_reaches_the_road_and_the_rest_holds(foot):
    from splatting.rider.ik.foot_down import ANKLE_ABOVE_GROUND_M, FOOT_OUT_M
    from splatting.rider.kinematics import JOINT_INDEX as J

    other = "right" if foot == "left" else "left"
    tg, lean, res = _solve(["none", foot])
    j = res.joints[1].double()
    a = math.radians(lean[1])
    assert lean[1] == pytest.approx(-8.0 if foot == "left" else 8.0)  # leaning towards the grounded foot
    c, s = math.cos(a), math.sin(a)
    Rx = torch.tensor([[1.0, 0, 0], [0, c, -s], [0, s, c]], dtype=torch.float64)
    ankle_world = Rx @ j[J[f"{foot}_ankle"]]
    assert abs(float(ankle_world[1]) - ANKLE_ABOVE_GROUND_M) < 0.03, f"ankle {float(ankle_world[1]):.3f} m above the road"
    assert abs(abs(float(ankle_world[2])) - FOOT_OUT_M) < 0.03 and np.sign(float(ankle_world[2])) == (-1 if foot == "left" else 1)
    assert float(res.ground_gap_m[1]) < 0.03 and float(res.ground_gap_m[0]) == 0.0
    # the held pairs: the other foot on its pedal, both hands, the pelvis
    for joint, key in ((f"{other}_ankle", f"pedal_{other}"), ("left_wrist", "handle_left"), ("right_wrist", "handle_right")):
        d = float(torch.linalg.vector_norm(j[J[joint]] - tg[key][1]))
        assert d < 0.03, f"{joint} {d * 100:.1f} cm off {key}"
    names = [n for n, f in res.free.items() if f[1]]
    assert names == [f"{foot}_ankle->pedal_{foot}"]
    # the grounded foot really left its pedal (the pedal is not on the road)
    assert float(torch.linalg.vector_norm(j[J[f"{foot}_ankle"]] - tg[f"pedal_{foot}"][1])) > 0.1


def test_no_foot_down_is_the_ordinary_ik():
    from splatting.bike.pose import posed_bike_keypoints
    from splatting.rider import ik
    from splatting.rider.skeleton_template import template_rest_joints

    tg, _, res = _solve(["none", "none"])
    rest = torch.as_tensor(template_rest_joints(1.80))
    plain = ik.solve(rest, tg, pairs=ik.DEFAULT_PAIRS, saddle_fit=True, iterations=40)
    assert torch.allclose(res.joints, plain.joints.to(res.joints.dtype), atol=1e-6)
    assert not any(bool(f.any()) for f in res.free.values())
    with pytest.raises(ValueError):
        from splatting.rider.ik.foot_down import solve_with_feet
        solve_with_feet(rest, tg, ["both"], ik.DEFAULT_PAIRS, [0, 0.3, 0], [0.0])


def test_a_stop_puts_a_foot_down_once_still_and_leans_onto_it(bikes):
    """The `stop` manoeuvre: foot_down is "left" / "right" exactly from the first frame below
    0.05 m/s, the bike leans onto that side (8 deg after the ramp), and a rendered frame's rider
    stands with that ankle on the road while the other foot stays on its pedal."""
    from helpers import street_config
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets
    from splatting.dataset.sequences.draw import FOOT_LEAN_RAMP_S, STOPPED_MPS, draw_sequence, frame_draw
    from splatting.rider.kinematics import JOINT_INDEX as J

    only = {m: 0.0 for m in ("straight", "turn_left", "turn_right", "cross", "overtake", "start", "swerve")}
    cfg = resolve_assets(validate(street_config(bikes, count=1, sequence={
        "enabled": True, "length": 60, "fps": 10.0, "manoeuvres": dict(only, stop=1.0)},
        street={"cyclists": [2, 2], "parked_bikes": [0, 0]})))
    sides = set()
    for seq in range(4):
        for inst in draw_sequence(cfg, seq)["instances"]:
            tr, feet = inst["traj"], np.array(inst["foot_down"])
            still = tr["speed"] < STOPPED_MPS
            assert still.any()
            first = int(np.flatnonzero(still)[0])
            assert (feet[:first] == "none").all() and (feet[first:] != "none").all() and len(set(feet[first:])) == 1
            side = feet[-1]
            sides.add(side)
            full = tr["t"] >= tr["t"][first] + FOOT_LEAN_RAMP_S
            want = -8.0 if side == "left" else 8.0
            assert np.allclose(inst["poses"][full, 2], want) and np.allclose(tr["theta_x_deg"][full], want)
            assert np.all(np.abs(inst["poses"][:first, 2]) < 1e-9)  # a straight ride upright before
    assert sides == {"left", "right"}
    # one stopped frame rendered through the street machinery's cyclist posing
    sd = draw_sequence(cfg, 0)
    inst = sd["instances"][0]
    f = len(inst["poses"]) - 1
    d = frame_draw(sd, f)["instances"][0]
    assert d["foot_down"] == inst["foot_down"][f] != "none"
    cyc = Assets(cfg).cyclist(d["bike"], d["rider"])
    fr = cyc.pose(torch.tensor([d["pose"]], dtype=torch.float64), feet=[d["foot_down"]])[0]
    side, other = d["foot_down"], "right" if d["foot_down"] == "left" else "left"
    ankle = np.asarray(fr.rider_joints[J[f"{side}_ankle"]])
    assert 0.02 < ankle[1] < 0.14, f"grounded ankle {ankle[1]:.3f} m above the road"
    assert np.linalg.norm(np.asarray(fr.rider_joints[J[f"{other}_ankle"]]) - np.asarray(fr.bike_keypoints[f"pedal_{other}"])) < 0.03
    # a batch mixing an arm signal (frame 0) and a foot down (frame 1): each frame gets its own
    up = list(d["pose"])
    up[2] = 0.0
    both = cyc.pose(torch.tensor([up, d["pose"]], dtype=torch.float64), signals=["left", "none"], feet=["none", side])
    w = np.asarray(both[0].rider_joints[J["left_wrist"]])
    assert np.linalg.norm(w - np.asarray(both[0].bike_keypoints["handle_left"])) > 0.2  # the signalling arm is out
    assert np.allclose(np.asarray(both[1].rider_joints), np.asarray(fr.rider_joints), atol=1e-4)

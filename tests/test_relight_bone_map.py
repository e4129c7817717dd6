"""Humanoid bone names -> the 24 SMPL joints (cyclist_formats/bone_map.py), the first piece of
`rider import`: Mixamo (with its namespace prefixes) and Rigify names, and the one-line errors."""
import pytest

from cyclist_formats.bone_map import SMPL_JOINTS, map_bones
from cyclist_formats.errors import UserError

MIXAMO = ["Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", "HeadTop_End"] + [
    side + b for side in ("Left", "Right") for b in ("UpLeg", "Leg", "Foot", "ToeBase", "Toe_End", "Shoulder", "Arm",
                                                    "ForeArm", "Hand", "HandIndex1", "HandMiddle1", "HandThumb1")]


@pytest.mark.parametrize("prefix", ["mixamorig:", "mixamorig1:", "mixamorig_", ""])
def test_mixamo_names_map_to_smpl(prefix):
    bones = [prefix + b for b in MIXAMO]
    m, scheme = map_bones(bones)
    assert scheme == "mixamo" and set(m) == set(SMPL_JOINTS)
    # spot checks against the documented table, by hand
    assert m["pelvis"] == prefix + "Hips"
    assert m["left_knee"] == prefix + "LeftLeg" and m["right_hip"] == prefix + "RightUpLeg"
    assert m["left_shoulder"] == prefix + "LeftArm" and m["left_collar"] == prefix + "LeftShoulder"
    assert m["spine3"] == prefix + "Spine2" and m["left_foot"] == prefix + "LeftToeBase"
    assert m["right_hand"] == prefix + "RightHandMiddle1"
    assert len(set(m.values())) == 24  # no bone serves two joints


def test_rigify_names_and_case():
    bones = ["DEF-spine", "DEF-spine.001", "DEF-spine.002", "DEF-spine.003", "DEF-spine.004", "DEF-spine.005",
             "DEF-spine.006"] + [f"DEF-{b}.{s}" for s in "LR" for b in ("thigh", "shin", "foot", "toe", "shoulder",
                                                                        "upper_arm", "forearm", "hand", "f_index.01")]
    m, scheme = map_bones([b.upper() if i % 3 == 0 else b for i, b in enumerate(bones)])
    assert scheme == "rigify"
    assert m["head"].lower() == "def-spine.006" and m["left_elbow"].lower() == "def-forearm.l"
    assert m["right_hand"].lower() == "def-f_index.01.r"  # the fallback when there is no middle finger


def test_missing_bones_are_named():
    bones = [b for b in MIXAMO if "Hand" not in b or b.endswith("Hand")]  # no finger bones
    with pytest.raises(UserError) as e:
        map_bones(["mixamorig:" + b for b in bones], "person.fbx")
    msg = str(e.value)
    assert "person.fbx" in msg and "left_hand (LeftHandMiddle1/LeftHandIndex1)" in msg and "right_hand" in msg
    assert "\n" not in msg and "left_wrist" not in msg


def test_non_humanoid_rig():
    with pytest.raises(UserError, match="not a humanoid rig.*0 of 24"):
        map_bones(["seat", "steer_top", "crank_axle", "pedal_left"])

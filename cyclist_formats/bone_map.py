"""Bone names of common humanoid rigs -> the 24 SMPL joints (docs/contract.md "Names"), pure Python.

The first piece of `rider import` (issue 16): a user's rigged human is usable only once each SMPL
joint has a bone.  Tables, per scheme, the bone whose head sits at the joint (first name found wins;
names are matched case-insensitively after dropping a namespace prefix such as "mixamorig:",
"mixamorig1:" or "mixamorig_"):

| SMPL joint | Mixamo | Rigify (DEF- bones) |
| --- | --- | --- |
| pelvis | Hips | DEF-spine |
| left_hip / right_hip | LeftUpLeg / RightUpLeg | DEF-thigh.L / .R |
| spine1 | Spine | DEF-spine.001 |
| left_knee / right_knee | LeftLeg / RightLeg | DEF-shin.L / .R |
| spine2 | Spine1 | DEF-spine.002 |
| left_ankle / right_ankle | LeftFoot / RightFoot | DEF-foot.L / .R |
| spine3 | Spine2 | DEF-spine.003 |
| left_foot / right_foot | LeftToeBase / RightToeBase | DEF-toe.L / .R |
| neck | Neck | DEF-spine.004 |
| left_collar / right_collar | LeftShoulder / RightShoulder | DEF-shoulder.L / .R |
| head | Head | DEF-spine.006 |
| left_shoulder / right_shoulder | LeftArm / RightArm | DEF-upper_arm.L / .R |
| left_elbow / right_elbow | LeftForeArm / RightForeArm | DEF-forearm.L / .R |
| left_wrist / right_wrist | LeftHand / RightHand | DEF-hand.L / .R |
| left_hand / right_hand | LeftHandMiddle1 (else LeftHandIndex1) | DEF-f_middle.01.L (else DEF-f_index.01.L) |

SMPL's left is the person's left.  Mixamo rigs with 3 spine bones map one to one; rigs with fewer
spine bones are reported as missing joints rather than guessed.
"""
import re

from .errors import UserError

SMPL_JOINTS = ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
               "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
               "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
               "left_hand", "right_hand")


def _sided(table, left, right):
    """{joint: names} with 'left_x'/'right_x' entries made from one template per side."""
    out = {}
    for joint, names in table.items():
        if joint.startswith("side_"):
            base = joint[len("side_"):]
            out["left_" + base] = tuple(n.format(S=left[0], s=left[1]) for n in names)
            out["right_" + base] = tuple(n.format(S=right[0], s=right[1]) for n in names)
        else:
            out[joint] = names
    return out


SCHEMES = {
    "mixamo": _sided({
        "pelvis": ("Hips",), "spine1": ("Spine",), "spine2": ("Spine1",), "spine3": ("Spine2",),
        "neck": ("Neck",), "head": ("Head",),
        "side_hip": ("{S}UpLeg",), "side_knee": ("{S}Leg",), "side_ankle": ("{S}Foot",), "side_foot": ("{S}ToeBase",),
        "side_collar": ("{S}Shoulder",), "side_shoulder": ("{S}Arm",), "side_elbow": ("{S}ForeArm",),
        "side_wrist": ("{S}Hand",), "side_hand": ("{S}HandMiddle1", "{S}HandIndex1"),
    }, ("Left", "L"), ("Right", "R")),
    "rigify": _sided({
        "pelvis": ("DEF-spine",), "spine1": ("DEF-spine.001",), "spine2": ("DEF-spine.002",),
        "spine3": ("DEF-spine.003",), "neck": ("DEF-spine.004",), "head": ("DEF-spine.006",),
        "side_hip": ("DEF-thigh.{s}",), "side_knee": ("DEF-shin.{s}",), "side_ankle": ("DEF-foot.{s}",),
        "side_foot": ("DEF-toe.{s}",), "side_collar": ("DEF-shoulder.{s}",), "side_shoulder": ("DEF-upper_arm.{s}",),
        "side_elbow": ("DEF-forearm.{s}",), "side_wrist": ("DEF-hand.{s}",),
        "side_hand": ("DEF-f_middle.01.{s}", "DEF-f_index.01.{s}"),
    }, ("Left", "L"), ("Right", "R")),
}

_PREFIX = re.compile(r"^(?:[^:]*:|mixamorig\d*_)", re.IGNORECASE)


def _key(name):
    return _PREFIX.sub("", name).lower()


def map_bones(bone_names, what="armature"):
    """Bone names of one armature -> {SMPL joint: bone name}, with the scheme that matched most.

    UserError (one line) when fewer than half the joints match any scheme ("not a humanoid rig") or
    when some joints have no bone (they are named, with the names looked for)."""
    by_key = {}
    for n in bone_names:
        by_key.setdefault(_key(n), n)
    best = None
    for scheme, table in SCHEMES.items():
        found = {j: next((by_key[_key(c)] for c in table[j] if _key(c) in by_key), None) for j in SMPL_JOINTS}
        score = sum(v is not None for v in found.values())
        if best is None or score > best[2]:
            best = (scheme, found, score)
    scheme, found, score = best
    if score < len(SMPL_JOINTS) // 2:
        sample = ", ".join(sorted(bone_names)[:8]) or "none"
        raise UserError(f"{what}: not a humanoid rig of a known naming scheme ({', '.join(SCHEMES)}): "
                        f"{score} of 24 SMPL joints found; its bones include {sample}")
    missing = [j for j in SMPL_JOINTS if found[j] is None]
    if missing:
        looked = "; ".join(f"{j} ({'/'.join(SCHEMES[scheme][j])})" for j in missing)
        raise UserError(f"{what}: {scheme} rig without bones for SMPL joints {looked}")
    return dict(found), scheme

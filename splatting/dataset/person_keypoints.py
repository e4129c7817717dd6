"""COCO-17 person keypoints of a posed rider, from fixed vertices of its body mesh.

COCO annotators click surface landmarks (the nose tip, the eyes, the ears) and limb centres where
a joint bends, not the skeleton's joint centres, so (as the SMPL-to-COCO regressors of the
pose-estimation literature do) every COCO point here is a fixed average of body-mesh vertices,
posed with the same linear blend skinning as the rider.  The vertex sets are chosen once per body
on the rest T-pose (canonical: X forward, Y up, Z to the body's right; arms along +-Z, legs down)
by these rules, so they are the same vertices for every pose and every frame:

| point | vertices (rest T-pose) |
| --- | --- |
| nose | the head vertex farthest forward (max X) within 1 cm of the mid-plane Z = 0 |
| left/right eye | the head vertex nearest (nose - 2.5 cm X, nose + 3.5 cm Y, -+3.2 cm Z) |
| left/right ear | the head vertex farthest to that side (min/max Z) between nose height and 4 cm above |
| left/right shoulder | ring of vertices within 1.5 cm (along Z) of the shoulder joint and 10 cm of it, upper half (Y above the joint): its mean sits on top of the shoulder, where COCO's shoulders are clicked |
| left/right elbow, wrist | ring within 1.5 cm (along Z, the T-pose arm axis) and 8 cm of the joint: its mean is the limb centre |
| left/right hip | vertices within 1.5 cm (along Y) of the hip joint's height, on its side, lateral of it (abs Z > abs Z_joint) and within 20 cm: COCO's hips sit lateral of the SMPL hip joints |
| left/right knee, ankle | ring within 1.5 cm (along Y, the leg axis) and 10 cm (knee) / 7 cm (ankle) of the joint |

"Head vertex" = dominant skinning weight on the head joint.  Left is -Z (the body's left).
The chosen vertex ids are stored per rider in the dataset's image records (`person_regressor`).
"""
import numpy as np
import torch

from splatting.rider.kinematics import JOINT_INDEX, forward_kinematics

COCO17 = ("nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
          "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip",
          "left_knee", "right_knee", "left_ankle", "right_ankle")
# COCO's person skeleton (1-based) and flip pairs, as in person_keypoints_val2017.json
COCO17_SKELETON = [[16, 14], [14, 12], [17, 15], [15, 13], [12, 13], [6, 12], [7, 13], [6, 7], [6, 8], [7, 9],
                   [8, 10], [9, 11], [2, 3], [1, 2], [1, 3], [2, 4], [3, 5], [4, 6], [5, 7]]
COCO17_FLIP = [[1, 2], [3, 4], [5, 6], [7, 8], [9, 10], [11, 12], [13, 14], [15, 16]]  # 0-based pairs
# COCO's OKS sigmas (cocoeval.py, Ronchi & Perona 2017), in COCO17 order
COCO17_SIGMAS = [0.026, 0.025, 0.025, 0.035, 0.035, 0.079, 0.079, 0.072, 0.072, 0.062, 0.062, 0.107, 0.107,
                 0.087, 0.087, 0.089, 0.089]
# depth-test tolerance (m) per point: how far under the rendered surface the point may lie and still
# count as visible.  Face points are on the skin (3 cm); limb centres lie about a limb radius deep
# (elbow, wrist 5 cm; knee, ankle 6 cm; shoulder top 7 cm); the lateral hip point ~8 cm into the thigh.
COCO17_TOLERANCE_M = [0.03, 0.03, 0.03, 0.03, 0.03, 0.07, 0.07, 0.05, 0.05, 0.05, 0.05, 0.08, 0.08,
                      0.06, 0.06, 0.06, 0.06]


def _ring(v, joint, axis, half_width, radius, extra=None):
    # a coarse mesh (an imported low-poly rider) may have no vertex within the band: widen it, up to 4x
    for grow in (1.0, 2.0, 4.0):
        sel = (np.abs(v[:, axis] - joint[axis]) < grow * half_width) & (np.linalg.norm(v - joint, axis=1) < grow * radius)
        if extra is not None:
            sel &= extra
        idx = np.nonzero(sel)[0]
        if len(idx):
            return idx
    raise ValueError("empty vertex ring")


def regressor(rider):
    """{COCO point: vertex index array} for a body.Rider (rest T-pose), by the module's rules."""
    n = rider.body_vertex_count or len(rider.vertices)  # the body's own vertices, not a helmet's or hair's
    v = rider.vertices[:n].double().numpy()
    J = rider.joints.double().numpy()
    dom = rider.weights[:n].argmax(1).numpy()
    head = np.nonzero(dom == JOINT_INDEX["head"])[0]
    hv = v[head]
    mid = np.abs(hv[:, 2]) < 0.01
    nose_i = head[mid][np.argmax(hv[mid, 0])]
    nose = v[nose_i]
    out = {"nose": np.array([nose_i])}
    for side, sz in (("left", -1.0), ("right", 1.0)):
        target = nose + np.array([-0.025, 0.035, sz * 0.032])
        out[f"{side}_eye"] = np.array([head[np.argmin(np.linalg.norm(hv - target, axis=1))]])
        band = (hv[:, 1] >= nose[1]) & (hv[:, 1] <= nose[1] + 0.04)
        cand = head[band]
        out[f"{side}_ear"] = np.array([cand[np.argmax(sz * v[cand, 2])]])
    for side in ("left", "right"):
        js = J[JOINT_INDEX[f"{side}_shoulder"]]
        out[f"{side}_shoulder"] = _ring(v, js, 2, 0.015, 0.10, v[:, 1] > js[1])
        for name in ("elbow", "wrist"):
            out[f"{side}_{name}"] = _ring(v, J[JOINT_INDEX[f"{side}_{name}"]], 2, 0.015, 0.08)
        jh = J[JOINT_INDEX[f"{side}_hip"]]
        lateral = (np.sign(v[:, 2]) == np.sign(jh[2])) & (np.abs(v[:, 2]) > abs(jh[2]))
        out[f"{side}_hip"] = _ring(v, jh, 1, 0.015, 0.20, lateral)
        out[f"{side}_knee"] = _ring(v, J[JOINT_INDEX[f"{side}_knee"]], 1, 0.015, 0.10)
        out[f"{side}_ankle"] = _ring(v, J[JOINT_INDEX[f"{side}_ankle"]], 1, 0.015, 0.07)
    return {k: out[k] for k in COCO17}


class PersonKeypoints:
    """The regressor of one body, ready to pose: (17, V_sel) averaging matrix over its vertices."""

    def __init__(self, rider):
        self.sets = regressor(rider)
        used = np.unique(np.concatenate(list(self.sets.values())))
        pos = {int(i): k for k, i in enumerate(used)}
        M = np.zeros((len(COCO17), len(used)))
        for r, name in enumerate(COCO17):
            for i in self.sets[name]:
                M[r, pos[int(i)]] = 1.0 / len(self.sets[name])
        self.M = torch.from_numpy(M)
        self.vertices = rider.vertices[used].double()
        self.weights = rider.weights[used].double()
        self.rest_joints = rider.joints.double()

    def record(self):
        return {k: [int(i) for i in v] for k, v in self.sets.items()}

    def posed(self, local_rotmats, root_trans):
        """(B, 24, 3, 3), (B, 3) -> (B, 17, 3) world points (the rider's own LBS)."""
        _, T = forward_kinematics(self.rest_joints, local_rotmats.double(), root_trans.double())
        A = torch.einsum("vj,bjkl->bvkl", self.weights, T[:, :, :3, :])
        pv = (A[..., :3] @ self.vertices[None, :, :, None]).squeeze(-1) + A[..., 3]
        return self.M[None] @ pv


class RecordingAvatar:
    """Wraps a RiderAvatar and keeps the last (local_rotmats, root_trans) it was posed with, so the
    mesh keypoints can be posed exactly like the avatar's Gaussians (Cyclist.pose poses the avatar
    through pose_tensors; everything else is passed through)."""

    def __init__(self, avatar):
        self._avatar = avatar
        self.last = self.rotations = None

    def __getattr__(self, k):
        return getattr(self._avatar, k)

    def __len__(self):
        return len(self._avatar)

    def pose_tensors(self, local_rotmats, root_trans=None):
        self.last = (local_rotmats.detach().clone(), None if root_trans is None else root_trans.detach().clone())
        out = self._avatar.pose_tensors(local_rotmats, root_trans)
        self.rotations = out["rotations"]  # (B, N, 3, 3): what turns a relit dataset's normals
        return out

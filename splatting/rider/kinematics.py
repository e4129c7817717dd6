"""SMPL-topology forward kinematics (24 joints), batched, in the canonical frame.

Shapes: rest_joints (24, 3) metres; local_rotmats (B, 24, 3, 3) (joint 0 = root orientation);
root_trans (B, 3). Returns joints (B, 24, 3) and world transforms (B, 24, 4, 4) that map a
rest-pose point attached to joint j to its posed position (the LBS bone transforms).
"""
import torch

JOINT_NAMES = ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2",
               "left_ankle", "right_ankle", "spine3", "left_foot", "right_foot", "neck",
               "left_collar", "right_collar", "head", "left_shoulder", "right_shoulder",
               "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hand", "right_hand")
PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)
JOINT_INDEX = {n: i for i, n in enumerate(JOINT_NAMES)}


def forward_kinematics(rest_joints, local_rotmats, root_trans=None, parents=PARENTS):
    """Posed joint positions and per-joint rigid transforms (rest -> posed).

    The root joint is rotated about its own rest position, then translated by root_trans.
    """
    B = local_rotmats.shape[0]
    dtype, dev = local_rotmats.dtype, local_rotmats.device
    rest = rest_joints.to(dtype=dtype, device=dev)
    offsets = rest.clone()
    offsets[1:] = rest[1:] - rest[list(parents[1:])]
    rots, pos = [None] * len(parents), [None] * len(parents)
    for j, p in enumerate(parents):
        if p < 0:
            rots[j] = local_rotmats[:, j]
            pos[j] = rest[j].expand(B, 3) + (0 if root_trans is None else root_trans.to(dtype))
        else:
            rots[j] = rots[p] @ local_rotmats[:, j]
            pos[j] = pos[p] + (rots[p] @ offsets[j].unsqueeze(-1)).squeeze(-1)
    R = torch.stack(rots, 1)  # (B, 24, 3, 3)
    joints = torch.stack(pos, 1)  # (B, 24, 3)
    T = torch.zeros(B, len(parents), 4, 4, dtype=dtype, device=dev)
    T[..., :3, :3] = R
    # x_posed = R_j (x_rest - rest_j) + joint_j
    T[..., :3, 3] = joints - (R @ rest.unsqueeze(-1)).squeeze(-1)
    T[..., 3, 3] = 1
    return joints, T

"""The rider: selectable people, SMPL-format motion, Gaussian avatar, keypoint IK on the bike."""

"""Keypoint inverse kinematics: hands on the handles, pelvis on the saddle, feet on the pedals.

The paper refines 11 joint rotations (spine1, shoulders, elbows, hips, knees, ankles) with Adam
(lr 0.05, 50 iterations) so that rider keypoints meet bike keypoints.  Here B frames are solved at
once; besides the 11 joints the root orientation and translation are free (the pelvis cannot reach
the saddle otherwise), and an optional saddle offset slides the seat along the seat tube.

Objectives (per frame, squared metres):
  pairs    sum over pairs of |joint - target|^2 (default pairs: DEFAULT_PAIRS)
  chamfer  the paper's symmetric Chamfer between the rider's and the bike's keypoint sets,
           0.5 * (sum_i min_j d_ij^2 + sum_j min_i d_ij^2), so it equals `pairs` when matched.
Priors: knees and elbows are hinges.  Their hinge angle theta = aa . axis (axis from the rest
skeleton, positive = flexion) is projected onto theta >= 0 after every step (they can never bend
backwards), penalised above HINGE_MAX_RAD, and the off-hinge part of their rotation is penalised;
a small quadratic prior pulls all free rotations toward the initial pose; a tiny one pulls the
saddle offset toward 0 so the seat only moves when the legs need it.
Per frame the iteration with the lowest loss is kept; frames still farther than CONVERGED_M from a
target after `iterations` steps go on (up to EXTEND_FACTOR x iterations) while they still gain.  Residuals are distances (m) between each
pair's joint and target at that iteration; a pair is flagged unreachable above `flag_threshold_m`.

Speed: only the kinematic chain that reaches the end-effectors is built, with constant joints
between two free ones folded into one precomputed rotation and offset, and processed level by
level (left and right limbs in one batched matmul); Adam is hand-written on one flat parameter
tensor.  See docs/ik.md for measured numbers.

Files: slots (parameter layout, hinges, default pairs), start (initial pose, saddle fit), chain
(the reduced forward kinematics), targets (input checks; the bike keypoints it reaches for are splatting.bike.pose.posed_bike_keypoints), solver (solve).
"""
from splatting.rider.ik.chain import ReducedChain
from splatting.rider.ik.slots import (CONVERGED_M, DEFAULT_PAIRS, EXACT_START_M, EXTEND_FACTOR, FLAG_THRESHOLD_M,
                                      HINGE_FLEX_DIRECTION, HINGE_MAX_RAD, IK_JOINTS, OBJECTIVES, PELVIS_ABOVE_SEAT_M, SEAT_RANGE_M, SLOT_JOINTS,
                                      hinge_axes, pair_name)
from splatting.rider.ik.solver import IKResult, solve
from splatting.rider.ik.start import analytic_init_pose, cycling_init_pose, saddle_offset_for_reach

__all__ = ["CONVERGED_M", "DEFAULT_PAIRS", "EXACT_START_M", "EXTEND_FACTOR", "FLAG_THRESHOLD_M", "HINGE_FLEX_DIRECTION", "HINGE_MAX_RAD", "IK_JOINTS", "IKResult",
           "OBJECTIVES", "PELVIS_ABOVE_SEAT_M", "ReducedChain", "SEAT_RANGE_M", "SLOT_JOINTS", "analytic_init_pose",
           "cycling_init_pose", "hinge_axes", "pair_name", "saddle_offset_for_reach", "solve"]

"""A cyclist = a posed bike + a rider fitted onto it by IK, as one Gaussian set with instance ids.

Per pose (8-DoF, degrees/metres): the IK runs in the bike's own frame (theta_p, theta_s only: the
analytic start assumes an upright bike facing +X), then the global transform H_g of the pose is
folded into the rider's root rotation and translation, so the rider's LBS lands it on the posed
bike in the world.  The bike is posed by BikeModel (H_s, H_p, H_g on its part Gaussians).
"""
from dataclasses import dataclass, replace

import numpy as np
import roma
import torch

from splatting.bike.pose import check_poses, posed_bike_keypoints
from cyclist_formats.errors import UserError
from splatting.gaussians.container import Gaussians
from splatting.rider import ik
from splatting.rider.ik.foot_down import FEET, combine, solve_with_feet
from splatting.rider.ik.signals import solve_with_signals
from splatting.rider.kinematics import JOINT_NAMES
from cyclist_formats.instances import IDS
from cyclist_formats import instances
from cyclist_formats.pose import POSE_FIELDS
from splatting.raster.api import eps2d_where

PART_IDS = {**instances.PART_IDS, **instances.SUB_PART_IDS}


@dataclass
class CyclistFrame:
    pose: np.ndarray              # (8,) degrees / metres
    gaussians: Gaussians          # bike parts then rider, world frame
    ids: torch.Tensor             # (N,) uint8 instance id per Gaussian
    bike_keypoints: dict          # name -> (3,) float64 world
    rider_joints: np.ndarray      # (24, 3) world, SMPL order, or None (bike only)
    ik: dict                      # {"residual_m": {pair: m}, "flagged": {pair: bool}, "seat_offset_m"} or None


SADDLE_RADIUS_M = 0.2  # the saddle (about 0.28 m long) lies within this of the seat-tube line
SADDLE_DEPTH_M = 0.12  # ... and within this below the seat keypoint along the line (springs too)
POST_RADIUS_M = 0.03   # the seat post: a thin cylinder on the line ...
POST_MARGIN_M = 0.04   # ... starting this far beyond the seat tube's nominal top (tube end, collar)


def saddle_slide(bike):
    """(mask (N,) bool, unit axis (3,) float64) of the frame Gaussians that slide with the IK's
    saddle auto-fit along the line crank_axle -> seat: the saddle (near the seat keypoint) and the
    exposed seat post (on the line, beyond the seat tube).  Only when the asset says where its
    seat tube ends (meta.json dimensions.seat_tube_m, written by the procedural generator);
    otherwise (None, None): nothing is modelled that the asset lacks.  Thresholds were checked
    against the generator's materials for all seven styles (tests/test_cyclist_saddle.py)."""
    dims = (getattr(bike, "meta", None) or {}).get("dimensions") or {}
    top = dims.get("seat_tube_m")
    kp = bike.keypoints
    if not isinstance(top, (int, float)) or "seat" not in kp or "crank_axle" not in kp or "frame" not in bike.part_names:
        return None, None
    u = kp["seat"] - kp["crank_axle"]
    seat_t = float(u.norm())
    u = u / seat_t
    a, e = bike.ranges[bike.part_names.index("frame")]
    rel = bike.canonical.means[a:e].double() - kp["crank_axle"]
    t = rel @ u
    radial = (rel - t[:, None] * u).norm(dim=1)
    saddle = (t > seat_t - SADDLE_DEPTH_M) & (radial < SADDLE_RADIUS_M)
    post = (t > float(top) + POST_MARGIN_M) & (radial < POST_RADIUS_M)
    mask = torch.zeros(len(bike), dtype=torch.bool)
    mask[a:e] = saddle | post
    return (mask, u) if mask.any() else (None, None)


def frame_eps2d(ids, bike, avatar):
    """rasterize's eps2d for a cyclist frame's Gaussians (ids: CyclistFrame.ids): each model drawn
    with the low-pass it was trained with (BikeModel.eps2d, RiderAvatar.eps2d); one number when
    they agree (the scalar path, the renders of before), else one per Gaussian."""
    return eps2d_where(ids != IDS["rider"], bike.eps2d, bike.eps2d if avatar is None else avatar.eps2d)


class Cyclist:
    def __init__(self, bike, avatar=None, ik_iterations=50):
        self.bike, self.avatar, self.ik_iterations = bike, avatar, int(ik_iterations)
        ids = torch.empty(len(bike), dtype=torch.uint8)
        for name, (a, e) in zip(bike.part_names, bike.ranges):
            ids[a:e] = PART_IDS[name]
        if avatar is not None:
            ids = torch.cat([ids, torch.full((len(avatar),), IDS["rider"], dtype=torch.uint8)])
            have = set(bike.keypoints)
            self.pairs = tuple((j, t) for j, t in ik.DEFAULT_PAIRS if t in have)
            self.saddle_fit = "seat" in have and "crank_axle" in have
            self.saddle_mask, self.saddle_axis = saddle_slide(bike) if self.saddle_fit else (None, None)
        self.ids = ids

    def fit_rider(self, poses, saddle_shared=False, init_local_aa=None, signals=None, feet=None):
        """IK of the rider onto the bike at poses (B, 8) (bike frame; H_g is applied later).
        signals: None or per pose one of ik.signals.SIGNALS (an arm signal: that hand off the bar).
        feet: None or per pose one of ik.foot_down.FEET (a foot on the road at a stop, beside the
        bike leaning by the pose's theta_X; that frame's arm signal, if any, is not shown)."""
        p = check_poses(poses).clone()
        if feet is not None and any(f != "none" for f in feet):
            return self._fit_with_feet(p, saddle_shared, init_local_aa, signals, list(feet))
        p[:, 2:] = 0.0
        targets = posed_bike_keypoints(self.bike.keypoints, p)
        if signals is not None and any(s != "none" for s in signals):
            return solve_with_signals(self.avatar.rest_joints, targets, list(signals), self.pairs,
                                      init_local_aa=init_local_aa, iterations=self.ik_iterations,
                                      saddle_fit=self.saddle_fit, saddle_shared=saddle_shared and self.saddle_fit)
        return ik.solve(self.avatar.rest_joints, targets, init_local_aa=init_local_aa, iterations=self.ik_iterations,
                        saddle_fit=self.saddle_fit, saddle_shared=saddle_shared and self.saddle_fit,
                        pairs=self.pairs)

    def _fit_with_feet(self, p, saddle_shared, init_local_aa, signals, feet):
        bad = [f for f in feet if f not in FEET]
        if bad or len(feet) != len(p):
            raise UserError(f"feet: one of {', '.join(FEET)} per pose, got {feet!r}")
        if "crank_axle" not in self.bike.keypoints or not self.bike.has_crank:
            raise UserError(f"{self.bike.source}: a foot down needs a bike with a crank")
        down = [b for b, f in enumerate(feet) if f != "none"]
        rest_idx = [b for b, f in enumerate(feet) if f == "none"]
        lean = [float(x) for x in p[:, 2]]
        q = p.clone()
        q[:, 2:] = 0.0
        sub = lambda t, idx: t if t is None or t.shape[0] != len(p) else t[idx]  # noqa: E731
        targets = posed_bike_keypoints(self.bike.keypoints, q[down])
        parts = [(down, solve_with_feet(self.avatar.rest_joints, targets, [feet[b] for b in down], self.pairs,
                                        self.bike.keypoints["crank_axle"].numpy(), [lean[b] for b in down],
                                        init_local_aa=sub(init_local_aa, down), iterations=self.ik_iterations,
                                        saddle_fit=self.saddle_fit, saddle_shared=saddle_shared and self.saddle_fit))]
        if rest_idx:
            parts.append((rest_idx, self.fit_rider(q[rest_idx], saddle_shared, sub(init_local_aa, rest_idx),
                                                   None if signals is None else [signals[b] for b in rest_idx])))
        return combine(len(p), parts)

    def pose(self, poses, saddle_shared=False, init_local_aa=None, fit=None, signals=None, wheel_deg=None, feet=None):
        """poses (B, 8) or (8,) -> list of B CyclistFrame.  fit: a fit_rider() result for exactly
        these poses (a sequence fits all its frames at once, then poses them chunk by chunk).
        signals: None or per pose an arm signal (fit_rider); the released hand's pair is left out
        of the frame's `ik` record, which then names the signal.  wheel_deg: per pose the wheel
        sub-parts' rolling angle (BikeModel.pose_tensors; default theta_p x gear ratio).  feet: per
        pose a foot on the road or "none" (fit_rider); the grounded foot's pedal pair is left out of
        the `ik` record as a released hand's is."""
        p = check_poses(poses)
        B = p.shape[0]
        bt = self.bike.pose_tensors(p, wheel_deg=wheel_deg)
        names = bt["keypoint_names"]
        frames = []
        rider_out = slide = None
        if self.avatar is not None:
            res = fit if fit is not None else self.fit_rider(p, saddle_shared, init_local_aa, signals, feet)
            Hg = self.bike.part_transforms(p)["frame"].float()  # H_g: the frame part is H_g alone
            Rg, tg = Hg[:, :3, :3], Hg[:, :3, 3]
            rot = roma.rotvec_to_rotmat(res.local_aa.float())
            rot[:, 0] = Rg @ rot[:, 0]
            rest0 = self.avatar.rest_joints[0]
            root = ((rest0 + res.root_trans.float())[:, None] @ Rg.transpose(1, 2))[:, 0] + tg - rest0
            joints = res.joints.float() @ Rg.transpose(1, 2) + tg[:, None]
            rider_out = (self.avatar.pose_tensors(rot, root), joints, res)
            if res.seat_offset is not None and self.saddle_mask is not None:
                # the fitted seat moves the saddle + post Gaussians and the seat keypoint with it
                slide = res.seat_offset.double()[:, None] * (Rg.double() @ self.saddle_axis)  # (B, 3) world
        for b in range(B):
            means = bt["means"][b]
            kp = {k: bt["keypoints"][b, j].numpy() for j, k in enumerate(names)}
            if slide is not None:
                means = means.clone()
                means[self.saddle_mask] += slide[b].to(means.dtype)
                kp["seat"] = kp["seat"] + slide[b].numpy()
            parts = [Gaussians(means, bt["quats"][b], bt["log_scales"], bt["opacity_logits"], bt["sh"][b])]
            joints = ikd = None
            if rider_out is not None:
                out, J, res = rider_out
                ag = self.avatar.gaussians
                parts.append(Gaussians(out["means"][b], out["quats"][b], ag.log_scales, ag.opacity_logits, out["sh"][b]))
                joints = J[b].double().numpy()
                free = {k for k, v in (res.free or {}).items() if bool(v[b])}
                ikd = {"residual_m": {k: float(v[b]) for k, v in res.residuals.items() if k not in free},
                       "flagged": {k: bool(v[b]) for k, v in res.flagged.items() if k not in free},
                       "seat_offset_m": None if res.seat_offset is None else float(res.seat_offset[b])}
                if signals is not None:
                    ikd["signal"] = signals[b]
            frames.append(CyclistFrame(p[b].numpy(), Gaussians.cat(parts), self.ids, kp, joints, ikd))
        return frames


def take_fit(res, idx):
    """The frames idx (a slice or index list) of an IKResult, as an IKResult."""
    pick = lambda t: None if t is None else t[idx]  # noqa: E731
    return replace(res, local_aa=res.local_aa[idx], root_trans=res.root_trans[idx], joints=res.joints[idx],
                   loss=res.loss[idx], residuals={k: v[idx] for k, v in res.residuals.items()},
                   flagged={k: v[idx] for k, v in res.flagged.items()}, seat_offset=pick(res.seat_offset),
                   free=None if res.free is None else {k: v[idx] for k, v in res.free.items()},
                   history=res.history[:, idx], seat=pick(res.seat))


def frame_record(frame, index, extra=None):
    """The docs/contract.md per-frame JSON object."""
    rec = {"frame": int(index), "pose": [float(x) for x in frame.pose], "pose_fields": list(POSE_FIELDS),
           "units": {"angles": "deg", "lengths": "m"}, "coordinate_frame": "world (canonical axes)",
           "bike_keypoints": {k: [float(x) for x in v] for k, v in frame.bike_keypoints.items()}}
    if frame.rider_joints is not None:
        rec["rider_joints"] = {n: [float(x) for x in frame.rider_joints[i]] for i, n in enumerate(JOINT_NAMES)}
        rec["ik"] = frame.ik
    if extra:
        rec.update(extra)
    return rec


def check_rider_fits(cyclist):
    if cyclist.avatar is not None and not cyclist.pairs:
        raise UserError(f"bike {cyclist.bike.bike_id} has none of the keypoints the rider IK needs")

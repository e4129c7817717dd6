"""The parametric bicycle: part Gaussians + keypoints re-posed by the 8-DoF pose (bike_pose.py).

Bike folder (docs/contract.md): gaussians/<part>.ply for frame, steering and crank, keypoints.json,
meta.json (bike_id, has_crank).  Rideables without a crank (kick scooter, motorcycle:
has_crank false, no crank.ply) accept theta_p and ignore it.

Optional sub-parts, used only when the asset provides them (nothing is modelled that the asset
lacks): gaussians/front_wheel.ply and rear_wheel.ply spin about their axles (parallel to Z) by
theta_p * meta.json "gear_ratio" in the rolling direction (front wheel also steers), or by an
explicit rolling angle per pose (pose_tensors(wheel_deg=...): a coasting bike's wheels turn while
its crank stands still; rolling without slip is wheel angle = distance / wheel radius);
gaussians/pedal_left.ply and pedal_right.ply follow their crank keypoint but stay level.
The 8-DoF pose itself is unchanged: the wheel angle is an extra input, never a ninth field.

Speed: everything pose-independent is prepared at load time.  Gaussians are stored feature-major
(means (3, N), quats (4, N), SH (K, N, 3)) because a small matrix times a wide matrix is several
times faster on CPU than the (N, 3) @ (3, 3) form (measured: 0.09 vs 0.6 ms for 100k means).
Posed Gaussians are therefore strided views (N innermost for means and quats; per SH coefficient
an (N, 3) block); call .contiguous() where a consumer needs it.
Log-scales and opacities do not depend on the pose and are shared with the model, not copied.
"""
import math
import os
from dataclasses import dataclass

import torch

from splatting.bike.pose import about_point, check_poses, compose, global_rigid, pose_rotations, rigid, steering_axis
from cyclist_formats import bike_folder
from cyclist_formats.errors import UserError
from splatting.gaussians.container import Gaussians, read_ply
from splatting.gaussians.sh_rotation import BANDS, sh_band_matrices
from splatting.raster.api import EPS2D
# the training-record rules live in training.record; these names stay importable from here
from splatting.training.record import check_model_eps2d, part_metrics_path, trained_antialiased, trained_eps2d  # noqa: F401

MAIN_PARTS = ("frame", "steering", "crank")
SUB_PARTS = ("front_wheel", "rear_wheel", "pedal_left", "pedal_right")
KEYPOINTS, CRANK_KEYPOINTS = bike_folder.KEYPOINTS, bike_folder.CRANK_KEYPOINTS  # docs/contract.md names
Z = (0.0, 0.0, 1.0)  # crank and wheel axles are parallel to canonical Z


@dataclass
class PosedBike:
    gaussians: Gaussians  # concatenation frame | steering | crank | sub-parts, world frame
    keypoints: dict  # name -> (3,) float64 tensor, world frame, metres


class BikeModel:
    """Load with BikeModel.load(bike_dir); pose with model.pose(poses)."""

    @classmethod
    def load(cls, bike_dir, bike_id=None, sh_degree=None, suffix=""):
        """suffix "_rest": the rest-trained parts gaussians/<part>_rest.ply that bike-posed-train
        starts from (the library's train tasks write those when its posed stage is on)."""
        bike_dir = os.fspath(bike_dir)
        if not os.path.isdir(bike_dir):
            raise UserError(f"no bike folder: {bike_dir}")
        meta = bike_folder.read_json(os.path.join(bike_dir, "meta.json"), "meta.json", f"missing meta.json: {os.path.join(bike_dir, 'meta.json')}")
        if not isinstance(meta, dict) or "bike_id" not in meta:
            raise UserError(f"{bike_dir}/meta.json has no bike_id")
        if bike_id is not None and str(bike_id) != str(meta["bike_id"]):
            raise UserError(f"bike id {bike_id!r} does not match {bike_dir}/meta.json bike_id {meta['bike_id']!r}")
        has_crank = meta.get("has_crank", True)
        if not isinstance(has_crank, bool):
            raise UserError(f"{bike_dir}/meta.json has_crank must be true or false, got {has_crank!r}")
        kp_doc = bike_folder.read_json(os.path.join(bike_dir, "keypoints.json"), "keypoints.json", f"missing keypoints.json: {os.path.join(bike_dir, 'keypoints.json')}")
        gdir = os.path.join(bike_dir, "gaussians")
        names = [p for p in MAIN_PARTS if p != "crank" or has_crank]
        for p in names:
            if not os.path.isfile(os.path.join(gdir, p + suffix + ".ply")):
                raise UserError(f"missing part file {os.path.join(gdir, p + suffix + '.ply')}"
                                + (" (meta.json has_crank is true)" if p == "crank" else ""))
        names += [p for p in SUB_PARTS if os.path.isfile(os.path.join(gdir, p + suffix + ".ply"))]
        parts = {p: read_ply(os.path.join(gdir, p + suffix + ".ply")) for p in names}
        return cls(parts, kp_doc, meta, sh_degree=sh_degree, source=bike_dir,
                   antialiased=trained_antialiased(gdir, [p + suffix for p in names]),
                   eps2d=trained_eps2d(gdir, {p: len(g) for p, g in parts.items()}, fine_tuned=suffix == ""))

    def __init__(self, parts, keypoints_doc, meta, sh_degree=None, source="<memory>", antialiased=False, eps2d=EPS2D):
        """parts: {part name: Gaussians}; keypoints_doc: the keypoints.json object; meta: meta.json.
        antialiased: the parts were trained with antialiased splatting, so they must be rendered
        with it (rasterize(antialiased=model.antialiased)); eps2d: the screen-space low-pass (px^2)
        they were trained with, drawn with it too (rasterize(eps2d=), per Gaussian in a scene with
        other models); load() reads both from the parts' metrics."""
        self.source = source
        self.antialiased = bool(antialiased)
        self.eps2d = check_model_eps2d(eps2d, source)
        self.meta = meta
        self.bike_id = str(meta.get("bike_id", ""))
        self.has_crank = "crank" in parts
        self.part_names = [p for p in MAIN_PARTS + SUB_PARTS if p in parts]
        if "frame" not in parts or "steering" not in parts:
            raise UserError(f"{source}: a bike needs frame and steering parts")
        if not self.has_crank and any(p in parts for p in ("pedal_left", "pedal_right")):
            raise UserError(f"{source}: pedal sub-parts without a crank")
        self._load_keypoints(keypoints_doc)
        self.gear_ratio = None
        if self.has_crank and any(p in parts for p in ("front_wheel", "rear_wheel")):
            g = meta.get("gear_ratio")
            if isinstance(g, bool) or not isinstance(g, (int, float)) or not math.isfinite(g) or g <= 0:
                raise UserError(f"{source}: wheel sub-parts need a positive meta.json gear_ratio, got {g!r}")
            self.gear_ratio = float(g)

        deg = max(parts[p].sh_degree for p in self.part_names) if sh_degree is None else int(sh_degree)
        canon = Gaussians.cat([parts[p].with_sh_degree(deg) for p in self.part_names])
        self.canonical = canon  # concatenated canonical Gaussians, (N, ...) contiguous
        self.sh_degree = deg
        self.ranges, a = [], 0
        for p in self.part_names:
            self.ranges.append((a, a + len(parts[p])))
            a += len(parts[p])
        # feature-major copies for the hot path (see module docstring)
        self._means = canon.means.T.contiguous()
        self._quats = canon.quats.T.contiguous()
        self._sh = canon.sh.permute(1, 0, 2).contiguous().view(canon.sh.shape[1], -1)  # (K, N*3)

    def _load_keypoints(self, doc):
        required = [k for k in KEYPOINTS if self.has_crank or k not in CRANK_KEYPOINTS + ("seat",)]
        arrays, part_of = bike_folder.parse_keypoints_doc(doc, self.has_crank, required, self.source)
        coords = {k: torch.from_numpy(v) for k, v in arrays.items()}
        self.steer_axis = steering_axis(coords["steer_bottom"], coords["steer_top"])  # UserError if degenerate
        self.keypoint_names = list(coords)
        self.keypoints = coords
        self._kp = torch.stack([coords[k] for k in self.keypoint_names])  # (n, 3) float64
        self._kp_part = [part_of[k] for k in self.keypoint_names]

    def __len__(self):
        return self._means.shape[1]

    # ------------------------------------------------------------ transforms

    @property
    def has_wheels(self):
        return "front_wheel" in self.part_names or "rear_wheel" in self.part_names

    def wheel_angles(self, poses, wheel_deg=None):
        """The wheels' rolling angle (degrees, + = forward) per pose: wheel_deg (B,) when given,
        else theta_p x gear_ratio (0 without a gear ratio: crankless rideables)."""
        p = check_poses(poses)
        if wheel_deg is None:
            return p[:, 0] * (self.gear_ratio or 0.0)
        w = torch.as_tensor(wheel_deg, dtype=torch.float64).reshape(-1)
        if w.shape[0] != p.shape[0] or not torch.isfinite(w).all():
            raise UserError(f"wheel_deg needs one finite angle per pose ({p.shape[0]}), got {tuple(w.shape)}")
        return w

    def _part_rigids(self, p, wheel_deg=None):
        """(B, 8) checked poses -> {part: (R (B,3,3), t (B,3), L (B,4,4))} float64.  'crank' is
        H_g H_p, or just H_g for crankless rideables (theta_p ignored).  wheel_deg: see
        wheel_angles."""
        kp = self.keypoints
        extra = []
        if self.has_wheels:  # wheel spin: forward rolling is a negative rotation about +Z
            extra = [(Z, -self.wheel_angles(p, wheel_deg) * (math.pi / 180.0))]
        R, L = pose_rotations(p, self.steer_axis, extra)
        g = global_rigid(R, L, p)
        out = {"frame": g, "steering": compose(g, about_point(R[:, 3], L[:, 3], kp["steer_bottom"]))}
        if "front_wheel" in self.part_names:
            out["front_wheel"] = compose(out["steering"], about_point(R[:, 5], L[:, 5], kp["front_axle"]))
        if "rear_wheel" in self.part_names:
            out["rear_wheel"] = compose(g, about_point(R[:, 5], L[:, 5], kp["rear_axle"]))
        if not self.has_crank:
            out["crank"] = g
            return out
        pedal = about_point(R[:, 4], L[:, 4], kp["crank_axle"])
        out["crank"] = compose(g, pedal)
        eye3, eye4 = torch.eye(3, dtype=torch.float64), torch.eye(4, dtype=torch.float64)
        for side in ("pedal_left", "pedal_right"):
            if side in self.part_names:  # translate with the crank, never rotate: pedals stay level
                shift = (pedal[0] @ kp[side]) + pedal[1] - kp[side]
                out[side] = compose(g, (eye3.expand(len(p), 3, 3), shift, eye4.expand(len(p), 4, 4)))
        return out

    def part_transforms(self, poses, wheel_deg=None):
        """(B, 8) or (8,) degrees/metres -> {part: (B, 4, 4) float64 homogeneous world-from-canonical}."""
        return {k: rigid(R, t) for k, (R, t, _) in self._part_rigids(check_poses(poses), wheel_deg).items()}

    # ------------------------------------------------------------ posing

    def pose_tensors(self, poses, reuse=None, wheel_deg=None):
        """Batched re-pose + compose.  poses (B, 8) or (8,) degrees/metres ->
        dict means (B, N, 3), quats (B, N, 4), sh (B, N, K, 3) [strided views],
        log_scales (N, 3), opacity_logits (N,) [shared, pose-independent],
        keypoints (B, n, 3) float64, keypoint_names [n], poses (B, 8) float64.

        reuse: a dict this method returned before for the same batch size; its tensors are
        overwritten instead of allocating new ones (fresh multi-MB allocations cost page faults
        that can exceed the arithmetic; a render loop that consumes each batch before posing
        the next one should pass its previous result).
        wheel_deg: (B,) rolling angles of the wheel sub-parts (default theta_p x gear_ratio)."""
        p = check_poses(poses)
        B, N = p.shape[0], len(self)
        rig = self._part_rigids(p, wheel_deg)
        dt = self._means.dtype
        R64 = torch.stack([rig[name][0] for name in self.part_names])  # (P, B, 3, 3)
        R = R64.to(dt)
        t = torch.stack([rig[name][1] for name in self.part_names]).to(dt)
        L = torch.stack([rig[name][2] for name in self.part_names]).to(dt)
        D = sh_band_matrices(R, self.sh_degree)  # per band (P, B, 2l+1, 2l+1)

        buffers = reuse["_buffers"] if reuse is not None else None
        if buffers is not None and (buffers[0].shape[0] != B or buffers[0].dtype != dt or buffers[0].shape[2] != N):
            raise ValueError("reuse= must come from pose_tensors of this model with the same batch size")
        if buffers is None:
            means = torch.empty(B, 3, N, dtype=dt)
            quats = torch.empty(B, 4, N, dtype=dt)
            sh = torch.empty((B,) + tuple(self._sh.shape), dtype=dt) if self.sh_degree > 0 else None  # (B, K, N*3)
        else:
            means, quats, sh = buffers
        mflat, qflat = means.view(B * 3, N), quats.view(B * 4, N)
        if sh is not None:
            sh[:, 0] = self._sh[0]  # DC is rotation invariant
        for i, (a, e) in enumerate(self.ranges):
            # all poses at once: (B*3, 3) @ (3, n) lands in rows b*3.. of the (B*3, N) output
            torch.addmm(t[i].reshape(B * 3, 1), R[i].reshape(B * 3, 3), self._means[:, a:e], out=mflat[:, a:e])
            torch.mm(L[i].reshape(B * 4, 4), self._quats[:, a:e], out=qflat[:, a:e])
            for l, Dl in enumerate(D, start=1):  # a part's SH band is one (2l+1, n*3) block
                s, z = BANDS[l]
                X = self._sh[s:z, 3 * a:3 * e]
                torch.bmm(Dl[i], X.expand(B, -1, -1), out=sh[:, s:z, 3 * a:3 * e])  # writes in place

        kpR = torch.stack([rig[part][0] for part in self._kp_part], 1)  # (B, n, 3, 3)
        kpt = torch.stack([rig[part][1] for part in self._kp_part], 1)
        return {
            "means": means.transpose(1, 2),
            "quats": quats.transpose(1, 2),
            "sh": sh.view(B, -1, N, 3).transpose(1, 2) if self.sh_degree > 0 else self.canonical.sh.expand(B, N, 1, 3),
            "log_scales": self.canonical.log_scales,
            "opacity_logits": self.canonical.opacity_logits,
            "keypoints": (kpR @ self._kp[..., None])[..., 0] + kpt,
            "keypoint_names": list(self.keypoint_names),
            "poses": p,
            "_buffers": (means, quats, sh),
        }

    def pose(self, poses, wheel_deg=None):
        """One pose (8,) -> PosedBike; a batch (B, 8) -> list of B PosedBike (views into one
        fresh batched allocation).  For long pose sequences, pose_tensors(chunk, reuse=previous)
        + posed_from_tensors avoids re-allocating (and page-faulting) tens of MB per pose."""
        try:
            single = torch.as_tensor(poses, dtype=torch.float64).dim() == 1
        except (TypeError, ValueError, RuntimeError):
            single = False  # pose_tensors raises the UserError
        if single and wheel_deg is not None:
            wheel_deg = torch.as_tensor(wheel_deg, dtype=torch.float64).reshape(1)
        out = self.pose_tensors(poses, wheel_deg=wheel_deg)
        res = [posed_from_tensors(out, b) for b in range(out["poses"].shape[0])]
        return res[0] if single else res


def present_parts(gdir):
    """The part names (BikeModel's order: MAIN_PARTS then SUB_PARTS) that have a <part>.ply in a
    bike's gaussians/ folder gdir."""
    return [p for p in MAIN_PARTS + SUB_PARTS if os.path.isfile(os.path.join(gdir, p + ".ply"))]


def posed_from_tensors(out, b):
    """Pose b of a pose_tensors() result as a PosedBike (views, no copies)."""
    g = Gaussians(means=out["means"][b], quats=out["quats"][b], log_scales=out["log_scales"],
                  opacity_logits=out["opacity_logits"], sh=out["sh"][b])
    return PosedBike(g, {k: out["keypoints"][b, j] for j, k in enumerate(out["keypoint_names"])})

"""Motion blur by smearing each Gaussian along its own motion (method B; docs/sequences.md, motion blur).

A Gaussian moving by d (relative to the camera) at constant speed during a box shutter is, time
averaged, its own Gaussian convolved with a uniform segment of length |d|: the segment's covariance
d d^T / 12 added to its 3D covariance is the moment-matched Gaussian of that (projected, it is the
blur along the projected screen velocity to first order).  Its opacity is scaled so that its
screen-space integral (what a blurred image conserves) stays: opacity x sqrt(det S2d) for an
antialiased Gaussian, opacity x sqrt(det(S2d + eps2d I)) otherwise (S2d the projected covariance).
Alpha compositing is not linear, so overlapping opaque Gaussians blur only approximately: an opaque
surface smeared becomes a stack of half-transparent ones.

d per Gaussian: its posed mean at the end of the exposure minus at its start (the cyclist's
trajectory, pedals with the crank) minus the ego camera's travel: one extra posing of the two
instants, one render.
"""
from dataclasses import replace

import torch

from splatting.dataset.frames import contact
from splatting.dataset.generate import make_sample
from splatting.dataset.sequences.draw import ego_camera, frame_draw
from splatting.rotations import quat_to_rotmat, rotmat_to_quat_wxyz


def _cov2d_det(cov, means, cam):
    """det of the projected 2D covariances (N,) of world covariances cov (N, 3, 3) at means (N, 3)."""
    R, T, K = cam.R.double(), cam.T.double(), cam.K.double()
    xc = means.double() @ R.T + T
    z = xc[:, 2].clamp_min(1e-3)
    J = torch.zeros(len(z), 2, 3, dtype=torch.float64)
    J[:, 0, 0], J[:, 0, 2] = K[0, 0] / z, -K[0, 0] * xc[:, 0] / z ** 2
    J[:, 1, 1], J[:, 1, 2] = K[1, 1] / z, -K[1, 1] * xc[:, 1] / z ** 2
    M = J @ R
    return M @ cov @ M.transpose(1, 2)


def smear(g, disp, cam, eps2d, antialiased):
    """Gaussians g (world) smeared along their displacements disp (N, 3) over the exposure."""
    q = g.quats.double()
    Rq = quat_to_rotmat(q / q.norm(dim=1, keepdim=True))
    cov = Rq @ (torch.exp(2 * g.log_scales.double())[:, :, None] * Rq.transpose(1, 2))
    d = disp.double()
    cov_b = cov + d[:, :, None] * d[:, None, :] / 12.0
    vals, vecs = torch.linalg.eigh(cov_b)
    vecs = vecs * torch.sign(torch.linalg.det(vecs))[:, None, None]  # a rotation (det +1)
    e = torch.as_tensor(eps2d, dtype=torch.float64).reshape(-1, 1, 1) * torch.eye(2, dtype=torch.float64)
    s0, s1 = _cov2d_det(cov, g.means, cam), _cov2d_det(cov_b, g.means, cam)
    aa = torch.as_tensor(antialiased, dtype=torch.bool).expand(len(g))
    det0 = torch.where(aa, torch.linalg.det(s0), torch.linalg.det(s0 + e))
    det1 = torch.where(aa, torch.linalg.det(s1), torch.linalg.det(s1 + e))
    ratio = torch.sqrt(det0.clamp_min(1e-30) / det1.clamp_min(1e-30)).clamp_max(1.0)
    op = (torch.sigmoid(g.opacity_logits.double()) * ratio).clamp(1e-6, 1 - 1e-6)
    dt = g.means.dtype
    return replace(g, quats=rotmat_to_quat_wxyz(vecs).to(dt), log_scales=(0.5 * torch.log(vals.clamp_min(1e-20))).to(dt),
                   opacity_logits=torch.logit(op).to(dt))


def displacements(cfg, assets, sd, f, exposure_s):
    """Per instance k: (N_k, 3) world displacement of its Gaussians over the exposure centred on
    frame f, relative to the ego camera."""
    from splatting.dataset.sequences.blur import pose_at
    t_f = f / float(cfg["sequence"]["fps"])
    out = []
    for inst in sd["instances"]:
        cyc = assets.cyclist(inst["bike"], inst["rider"])
        poses = [pose_at(inst, t_f + s * exposure_s / 2) for s in (-1, 1)]
        if cfg["mode"] == "frames":
            poses = [contact.seat(cyc.bike.keypoints, p) for p in poses]
        sig = [inst["signal"][f]] * 2 if "signal" in inst else None
        a, b = cyc.pose(torch.tensor(poses, dtype=torch.float64),
                        signals=sig if inst["rider"] is not None and sig and sig[0] != "none" else None)
        d = (b.gaussians.means - a.gaussians.means).double()
        d[:, 2] -= sd["ego_speed"] * exposure_s  # the camera's travel: relative motion
        out.append(d)
    return out


def velocity_blurred_sample(cfg, index, assets, sd, f, exposure_s):
    """make_sample of frame f with every instance's Gaussians smeared over the exposure (one render;
    the labels are those of that render)."""
    disp = displacements(cfg, assets, sd, f, exposure_s)

    def hook(k, g, idx, cam, eps2d, antialiased):
        d = disp[k] if idx is None else disp[k].index_select(0, idx)
        return smear(g, d, cam, eps2d, antialiased)
    seq = index // int(cfg["sequence"]["length"])
    return make_sample(cfg, index, assets, drawn=frame_draw(sd, f), camera=ego_camera(sd, f), look_index=seq,
                       smear=hook)

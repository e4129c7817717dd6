"""Rotation helpers shared by every stage (torch).  Quaternions are wxyz, the INRIA .ply order.

roma where it is as fast; two measured fast paths are kept:
- quat_to_rotmat: the closed form on unbound components (the rasterizer's projection and the
  densifier call it on every Gaussian each step; roma.unitquat_to_rotmat wants xyzw and a reorder);
- rodrigues: ~3x fewer ops than roma.rotvec_to_rotmat (measured 0.05 vs 0.15 ms forward+backward
  for 12 rotations), which matters in the ~1 ms IK iteration.
"""
import roma
import torch


def quat_to_rotmat(q):
    """(..., 4) wxyz unit quaternions -> (..., 3, 3)."""
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], -1).reshape(q.shape[:-1] + (3, 3))


def rotmat_to_quat_wxyz(R):
    """(..., 3, 3) -> unit quaternions (..., 4) wxyz."""
    return roma.quat_xyzw_to_wxyz(roma.rotmat_to_unitquat(R))


def quat_mul(p, q):
    """Hamilton product of wxyz quaternions (..., 4)."""
    pw, px, py, pz = p.unbind(-1)
    qw, qx, qy, qz = q.unbind(-1)
    return torch.stack([pw * qw - px * qx - py * qy - pz * qz,
                        pw * qx + px * qw + py * qz - pz * qy,
                        pw * qy - px * qz + py * qw + pz * qx,
                        pw * qz + px * qy - py * qx + pz * qw], -1)


def quat_left_matrix(q):
    """wxyz (..., 4) -> L (..., 4, 4) with q * p == L @ p (Hamilton product)."""
    w, x, y, z = q.unbind(-1)
    rows = [[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]]
    return torch.stack([torch.stack(r, -1) for r in rows], -2)


def axis_angle_to_rotmat(aa):
    """(..., 3) axis-angle -> (..., 3, 3) (roma)."""
    return roma.rotvec_to_rotmat(aa)


def rotmat_to_axis_angle(R):
    """(..., 3, 3) -> (..., 3) axis-angle (roma)."""
    return roma.rotmat_to_rotvec(R)


def rodrigues(aa):
    """(..., 3) axis-angle -> (..., 3, 3), the fast path (see the module docstring)."""
    t2 = (aa * aa).sum(-1, keepdim=True) + 1e-12
    t = t2.sqrt()
    a = (torch.sin(t) / t)[..., None]
    b = (2.0 * torch.sin(0.5 * t) ** 2 / t2)[..., None]  # (1 - cos t) / t^2 without cancellation
    x, y, z = aa.unbind(-1)
    o = torch.zeros_like(x)
    K = torch.stack([o, -z, y, z, o, -x, -y, x, o], -1).unflatten(-1, (3, 3))
    return torch.eye(3, dtype=aa.dtype) + a * K + b * (K @ K)

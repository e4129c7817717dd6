"""Exact rotation of real SH coefficients (degrees 0-3, INRIA basis and order of splatting/sh.py).

Rotating a Gaussian by R must rotate its colour lobe too: the new coefficients c' must satisfy
eval_sh(c', R d) == eval_sh(c, d) for every direction d.  Each band l is closed under rotation,
so there is a (2l+1)x(2l+1) matrix D_l(R) with c'_l = D_l(R) c_l.

Method: we need Y_l(d) . c' = Y_l(R^T d) . c for all d.  Writing that at fixed sample directions
S (rows; more than 2l+1 of them, so the system is over-determined and well conditioned) gives
Y_l(S) c' = Y_l(S R) c  (row s R == (R^T s)^T), hence D_l(R) = pinv(Y_l(S)) @ Y_l(S R).
pinv(Y_l(S)) is fixed (computed once, float64); per rotation the cost is one basis evaluation at
|S| directions and one small matmul, batched over any number of rotations.  The result is exact
(up to floating point), not a fit: Y_l(R^T .) lies in the band-l space, so the system is consistent.
"""
import functools
import math

import torch

from splatting.gaussians.sh import sh_basis

BANDS = {1: (1, 4), 2: (4, 9), 3: (9, 16)}  # coefficient index range of each band
N_SAMPLES = 32  # >= 7 (largest band), over-determined for conditioning


@functools.lru_cache(maxsize=None)
def _samples_and_pinv():
    """Fibonacci-sphere sample directions (N_SAMPLES, 3) and per-band pinv, float64."""
    i = torch.arange(N_SAMPLES, dtype=torch.float64) + 0.5
    y = 1.0 - 2.0 * i / N_SAMPLES
    r = torch.sqrt(1.0 - y * y)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    s = torch.stack([r * torch.cos(phi), y, r * torch.sin(phi)], -1)
    basis = sh_basis(s, 3)
    pinvs = {l: torch.linalg.pinv(basis[:, a:b]) for l, (a, b) in BANDS.items()}
    return s, pinvs


def sh_band_matrices(R, degree):
    """R (..., 3, 3) rotation matrices -> [D_1 (..., 3, 3), D_2 (..., 5, 5), D_3 (..., 7, 7)][:degree].

    c'_l = D_l @ c_l rotates band-l coefficients (coefficient axis first, colour channels after).
    """
    if degree == 0:
        return []
    s, pinvs = _samples_and_pinv()
    s = s.to(R.dtype)
    rotated = s @ R  # row s_j R == (R^T s_j)^T
    basis = sh_basis(rotated, degree)  # (..., S, K)
    out = []
    for l in range(1, degree + 1):
        a, b = BANDS[l]
        out.append(pinvs[l].to(R.dtype) @ basis[..., a:b])
    return out


def sh_rotation_matrix(R, degree):
    """R (..., 3, 3) -> block-diagonal (..., K, K), K = (degree+1)**2, with 1 for the DC term."""
    k = (degree + 1) ** 2
    M = R.new_zeros(R.shape[:-2] + (k, k))
    M[..., 0, 0] = 1.0
    for l, D in enumerate(sh_band_matrices(R, degree), start=1):
        a, b = BANDS[l]
        M[..., a:b, a:b] = D
    return M


def rotate_sh(sh, R):
    """sh (..., K, 3) coefficients, R (..., 3, 3) broadcastable to sh's leading dims -> rotated sh.

    One R for all Gaussians: R (3, 3); one per Gaussian: R (N, 3, 3); a batch of poses over a
    shared set: sh (N, K, 3) with R (B, 1, 3, 3) gives (B, N, K, 3).
    """
    k = sh.shape[-2]
    degree = int(round(math.sqrt(k))) - 1
    if (degree + 1) ** 2 != k:
        raise ValueError(f"sh has {k} coefficients per channel, not a whole SH degree")
    if degree == 0:
        return sh.clone()
    shape = torch.broadcast_shapes(sh.shape[:-2], R.shape[:-2])
    out = sh.new_empty(shape + sh.shape[-2:])
    out[..., 0, :] = sh[..., 0, :]
    for l, D in enumerate(sh_band_matrices(R.to(sh.dtype), degree), start=1):
        a, b = BANDS[l]
        out[..., a:b, :] = D @ sh[..., a:b, :]
    return out

"""The one place where the canonical bike frame meets Blender's frame (docs/contract.md).

Canonical: X forward, Y up, Z to the rider's right.  Blender: Z up.
Blender (x, y, z) = canonical (X, -Z, Y).  Everything written to disk is canonical.
numpy only, so tests and non-Blender code can use it too.
"""
import numpy as np

# C maps canonical coordinates to Blender coordinates: b = C @ c.
C = np.array([[1.0, 0.0, 0.0],
              [0.0, 0.0, -1.0],
              [0.0, 1.0, 0.0]])
C_INV = C.T  # orthonormal, det +1 (a proper rotation: +90 deg about X)


def to_blender(p):
    """Canonical point(s) (..., 3) -> Blender point(s)."""
    return np.asarray(p, dtype=float) @ C.T


def to_canonical(p):
    """Blender point(s) (..., 3) -> canonical point(s)."""
    return np.asarray(p, dtype=float) @ C_INV.T


def _conjugate(m, A, A_inv):
    """A 4x4 (or 3x3) transform m expressed in the frame A maps into: A m A^-1."""
    m = np.asarray(m, dtype=float)
    if m.shape == (3, 3):
        return A @ m @ A_inv
    a4, a4_inv = np.eye(4), np.eye(4)
    a4[:3, :3], a4_inv[:3, :3] = A, A_inv
    return a4 @ m @ a4_inv


def matrix_to_blender(m):
    """A canonical 4x4 (or 3x3) transform -> the same motion expressed in Blender's frame."""
    return _conjugate(m, C, C_INV)


def matrix_to_canonical(m):
    """A Blender 4x4 (or 3x3) transform -> the same motion in the canonical frame."""
    return _conjugate(m, C_INV, C)

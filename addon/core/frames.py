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


def matrix_to_blender(m):
    """A canonical 4x4 (or 3x3) transform -> the same motion expressed in Blender's frame."""
    m = np.asarray(m, dtype=float)
    if m.shape == (3, 3):
        return C @ m @ C_INV
    c4 = np.eye(4)
    c4[:3, :3] = C
    return c4 @ m @ c4.T


def matrix_to_canonical(m):
    """A Blender 4x4 (or 3x3) transform -> the same motion in the canonical frame."""
    m = np.asarray(m, dtype=float)
    if m.shape == (3, 3):
        return C_INV @ m @ C
    c4 = np.eye(4)
    c4[:3, :3] = C_INV
    return c4 @ m @ c4.T

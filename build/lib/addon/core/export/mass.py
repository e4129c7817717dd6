"""Volume, centre of mass and inertia tensor of triangle meshes (numpy only).

Procedural and curated bike parts are many separate closed shells (tubes, spokes, rims) whose
windings are not all outward, and imported models may hold open shells.  So a part's mesh is
split into connected shells (vertices welded by position first); each closed shell (every edge
shared by exactly two triangles with opposite directions) counts with the absolute value of its
signed volume, which fixes inward winding; an open shell has no inside, so a caller-supplied
convex hull of it stands in (the bpy side uses bmesh.ops.convex_hull).  Overlapping shells are
counted twice (no CSG union): parts touch where tubes meet, which adds a few percent.

Integrals over signed tetrahedra (origin, a, b, c), the standard closed forms (Tonon 2004):
V = det[a b c] / 6, integral of x = V (a + b + c) / 4, integral of x_i x_j =
V / 20 (a_i a_j + b_i b_j + c_i c_j + s_i s_j) with s = a + b + c.
"""
from dataclasses import dataclass

import numpy as np

WELD_M = 1e-7  # vertices closer than this (per axis) are one vertex when finding shells


@dataclass
class MassProperties:
    volume: float  # m^3
    mass: float  # kg
    com: np.ndarray  # (3,) m, in the mesh's frame
    inertia: np.ndarray  # (3, 3) kg m^2 about the centre of mass, axes of the mesh's frame
    shells: int  # closed shells counted as they are
    open_shells: int  # open shells replaced by their convex hulls


def weld(verts, tris, tol=WELD_M):
    """Merge vertices that agree to `tol`: (verts (M, 3), tris (T, 3) into them)."""
    key = np.round(np.asarray(verts, float) / tol).astype(np.int64)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    out = np.zeros((len(uniq), 3))
    np.add.at(out, inv, verts)
    out /= np.bincount(inv, minlength=len(uniq))[:, None]
    return out, inv[np.asarray(tris)]


def shells(n_verts, tris):
    """Connected components of a triangle mesh -> label per triangle (0..K-1)."""
    lab = np.arange(n_verts)
    while True:  # min-label propagation over triangles with pointer jumping
        m = lab[tris].min(1)
        new = lab.copy()
        for c in range(3):
            np.minimum.at(new, tris[:, c], m)
        new = new[new]
        if np.array_equal(new, lab):
            break
        lab = new
    _, tri_lab = np.unique(lab[tris[:, 0]], return_inverse=True)
    return tri_lab.reshape(-1)


def is_closed(tris):
    """Every directed edge appears once and its reverse once: closed and consistently wound."""
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    if len(np.unique(e, axis=0)) != len(e):
        return False  # an edge used twice in the same direction, or more than twice
    fwd = set(map(tuple, e))
    return all((b, a) in fwd for a, b in e)


def integrals(verts, tris):
    """Signed (volume, first moment (3,), second moment S (3, 3) = integral x x^T) of a shell."""
    a, b, c = (verts[tris[:, k]] for k in range(3))
    v = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    s = a + b + c
    first = (v[:, None] * s).sum(0) / 4.0
    S = np.einsum("t,ti,tj->ij", v, a, a) + np.einsum("t,ti,tj->ij", v, b, b) \
        + np.einsum("t,ti,tj->ij", v, c, c) + np.einsum("t,ti,tj->ij", v, s, s)
    return v.sum(), first, S / 20.0


def mass_properties(verts, tris, density, hull=None):
    """Mass properties of a part's triangles at `density` kg/m^3.

    hull(verts (k, 3)) -> (hull_verts, hull_tris) closes open shells; without one an open shell
    is an error (ValueError), never silently dropped.
    """
    verts, tris = weld(np.asarray(verts, float), np.asarray(tris, np.int64))
    lab = shells(len(verts), tris)
    V, M1, S = 0.0, np.zeros(3), np.zeros((3, 3))
    n_open = 0
    for k in range(lab.max() + 1 if len(lab) else 0):
        t = tris[lab == k]
        if is_closed(t):
            v, m1, s = integrals(verts, t)
        else:
            if hull is None:
                raise ValueError("open shell and no convex hull function")
            hv, ht = hull(verts[np.unique(t)])
            v, m1, s = integrals(np.asarray(hv, float), np.asarray(ht, np.int64))
            n_open += 1
        sign = 1.0 if v >= 0 else -1.0  # inward-wound shell: all its integrals flip sign
        V, M1, S = V + sign * v, M1 + sign * m1, S + sign * s
    if not V > 0:
        raise ValueError("the mesh encloses no volume")
    com = M1 / V
    Sc = density * (S - V * np.outer(com, com))  # second moment about the centre of mass
    inertia = np.trace(Sc) * np.eye(3) - Sc
    return MassProperties(V, density * V, com, inertia, int(lab.max() + 1 - n_open) if len(lab) else 0, n_open)

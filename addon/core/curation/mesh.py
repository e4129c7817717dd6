"""Triangle-soup helpers (numpy, no bpy): welding, connected components, per-component stats.

Imported models arrive with vertices split at UV seams, flat-shaded faces and material
boundaries (glTF stores one primitive per material), so connectivity is computed on vertices
welded by position, never on the file's own vertex indices.
"""
from dataclasses import dataclass

import numpy as np


def triangle_areas(V, T):
    a, b, c = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def weld(V, rel_tol=1e-6):
    """Map each vertex to a representative of the vertices at the same position.

    Returns (inverse, unique_positions): V[i] ~ unique_positions[inverse[i]].  The grid step is
    rel_tol times the bounding-box diagonal, so welding works at any model scale.
    """
    V = np.asarray(V, float)
    if len(V) == 0:
        return np.zeros(0, int), V
    diag = float(np.linalg.norm(V.max(0) - V.min(0))) or 1.0
    keys = np.round((V - V.min(0)) / (diag * rel_tol)).astype(np.int64)
    uniq, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return inverse.reshape(-1), V[first]


def connected_components(n_vertices, T):
    """Component label (0..k-1) per vertex of a triangle list T (k, 3); isolated vertices get
    their own labels.  Min-label propagation with pointer jumping (numpy only, no scipy)."""
    lab = np.arange(n_vertices)
    if len(T):
        a = np.concatenate([T[:, 0], T[:, 1], T[:, 2]])
        b = np.concatenate([T[:, 1], T[:, 2], T[:, 0]])
        while True:
            m = np.minimum(lab[a], lab[b])
            new = lab.copy()
            np.minimum.at(new, a, m)
            np.minimum.at(new, b, m)
            while True:  # pointer jumping: follow labels to their roots
                nxt = new[new]
                if np.array_equal(nxt, new):
                    break
                new = nxt
            if np.array_equal(new, lab):
                break
            lab = new
    _, comp = np.unique(lab, return_inverse=True)
    return comp.reshape(-1)


@dataclass
class Component:
    index: int
    verts: np.ndarray        # indices into the welded vertex array
    tris: np.ndarray         # indices into the triangle array
    area: float
    centroid: np.ndarray     # area-weighted surface centroid
    bbox: np.ndarray         # (2, 3) min, max of its vertices
    axes: np.ndarray         # (3, 3) principal directions (rows), largest spread first
    spread: np.ndarray       # (3,) standard deviations of the vertices along those axes
    centre: np.ndarray       # mean of its (welded) vertices


class Soup:
    """A welded triangle mesh with its connected components.

    V: (n, 3) float, T: (m, 3) int indices into V (file order, not welded).
    Attributes: P (welded positions), TW (triangles on welded indices), area (m,), comp_of_tri
    (m,), comps (list of Component), comp_of_vert (len(P),).
    """

    def __init__(self, V, T, rel_tol=1e-6):
        V = np.asarray(V, float)
        T = np.asarray(T, np.int64).reshape(-1, 3)
        inv, self.P = weld(V, rel_tol)
        self.TW = inv[T] if len(T) else T
        self.area = triangle_areas(self.P, self.TW) if len(T) else np.zeros(0)
        self.comp_of_vert = connected_components(len(self.P), self.TW)
        self.comp_of_tri = self.comp_of_vert[self.TW[:, 0]] if len(T) else np.zeros(0, int)
        self.comps = self._stats()

    def _stats(self):
        P, TW = self.P, self.TW
        k = int(self.comp_of_vert.max()) + 1 if len(P) else 0
        vorder = np.argsort(self.comp_of_vert, kind="stable")
        vsplit = np.split(vorder, np.cumsum(np.bincount(self.comp_of_vert, minlength=k))[:-1])
        torder = np.argsort(self.comp_of_tri, kind="stable")
        tsplit = np.split(torder, np.cumsum(np.bincount(self.comp_of_tri, minlength=k))[:-1])
        tri_c = P[TW].mean(1) if len(TW) else np.zeros((0, 3))
        comps = []
        for i in range(k):
            vi, ti = vsplit[i], tsplit[i]
            if len(ti) == 0:
                continue  # stray vertex without faces
            pts = P[vi]
            a = self.area[ti]
            A = float(a.sum())
            cen = (tri_c[ti] * a[:, None]).sum(0) / A if A > 0 else pts.mean(0)
            mu = pts.mean(0)
            if len(pts) >= 3:
                w, v = np.linalg.eigh(np.cov((pts - mu).T, bias=True))
                order = np.argsort(w)[::-1]
                axes, spread = v[:, order].T, np.sqrt(np.maximum(w[order], 0))
            else:
                axes, spread = np.eye(3), np.zeros(3)
            comps.append(Component(i, vi, ti, A, cen, np.stack([pts.min(0), pts.max(0)]), axes, spread, mu))
        return comps

    def vert_mask(self, comp_mask):
        """Per-vertex bool from a bool per entry of self.comps."""
        full = np.zeros(int(self.comp_of_vert.max()) + 1 if len(self.P) else 0, bool)
        full[[c.index for c in self.comps]] = comp_mask
        return full[self.comp_of_vert]

    def tri_mask(self, comp_mask):
        full = np.zeros(int(self.comp_of_vert.max()) + 1 if len(self.P) else 0, bool)
        full[[c.index for c in self.comps]] = comp_mask
        return full[self.comp_of_tri]

    def transformed_points(self, M):
        """Welded positions under a 4x4 similarity M (row vectors)."""
        return self.P @ M[:3, :3].T + M[:3, 3]


def dihedral_angles(soup):
    """Angle (degrees, 0-90, orientation-free: flipped faces do not count) between the two faces
    of every welded edge shared by exactly two faces."""
    P, TW = soup.P, soup.TW
    n = np.cross(P[TW[:, 1]] - P[TW[:, 0]], P[TW[:, 2]] - P[TW[:, 0]])
    a = np.linalg.norm(n, axis=1)
    ok = a > 0
    n, TW = n[ok] / a[ok, None], TW[ok]
    e = np.sort(np.concatenate([TW[:, [0, 1]], TW[:, [1, 2]], TW[:, [2, 0]]]), 1)
    f = np.tile(np.arange(len(TW)), 3)
    key = e[:, 0] * (len(P) + 1) + e[:, 1]
    o = np.argsort(key, kind="stable")
    k = key[o]
    pair = np.nonzero(k[1:] == k[:-1])[0]
    pair = pair[(pair + 2 >= len(k)) | (k[np.minimum(pair + 2, len(k) - 1)] != k[pair])]   # exactly two faces
    f1, f2 = f[o][pair], f[o][pair + 1]
    return np.degrees(np.arccos(np.clip(np.abs((n[f1] * n[f2]).sum(1)), 0, 1)))

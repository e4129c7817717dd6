"""Hidden helper geometry of exported characters (numpy only): faces that are not the person.

MakeHuman / MPFB exports often keep MakeHuman's helper geometry in the body mesh: a skirt and tights
shell around the body and a small cube at every joint (one below each foot), which MakeHuman itself
hides.  They are separate connected pieces of the mesh whose UVs are squeezed into a tiny corner of
the texture: their texel density (texture area per surface area) is hundreds of times below the
body's.  `helper_faces` finds such pieces: textured connected components whose density is below
HELPER_DENSITY_RATIO of the mesh's high (area-weighted 90th percentile) density.  Palette-textured
characters, whose every part maps to a few texels, have a low reference too and keep everything; and
nothing is dropped when that would leave a joint without the vertices it moves most (the body itself
would go).
"""
import numpy as np

HELPER_DENSITY_RATIO = 1.0 / 30.0


def components(n_vertices, faces):
    """Connected component label per vertex (union-find over the faces' edges)."""
    parent = np.arange(n_vertices)

    def find(x):
        root = x
        while parent[root] != root:
            root = parent[root]
        while parent[x] != root:
            parent[x], x = root, parent[x]
        return root

    for a, b, c in faces:
        ra, rb, rc = find(a), find(b), find(c)
        r = min(ra, rb, rc)
        parent[ra] = parent[rb] = parent[rc] = r
    return np.array([find(i) for i in range(n_vertices)])


def helper_faces(V, F, UV, FT, W):
    """Boolean mask over faces: the helper pieces to drop (all False when none is found)."""
    drop = np.zeros(len(F), bool)
    textured = FT >= 0
    if textured.sum() < 2:
        return drop
    T = V[F]
    area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    d1, d2 = UV[:, 1] - UV[:, 0], UV[:, 2] - UV[:, 0]
    uv_area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1])
    dens = uv_area / np.maximum(area, 1e-12)
    t = np.flatnonzero(textured & (area > 0))
    if not len(t):
        return drop
    order = t[np.argsort(dens[t])]
    cum = np.cumsum(area[order])
    ref = dens[order[np.searchsorted(cum, 0.9 * cum[-1])]]
    if ref <= 0:
        return drop
    label = components(len(V), F)[F[:, 0]]
    ids, inv = np.unique(label, return_inverse=True)
    c_area = np.bincount(inv, area, len(ids))
    c_uv = np.bincount(inv, uv_area, len(ids))
    c_textured = np.bincount(inv, textured, len(ids)) == np.bincount(inv, None, len(ids))
    low = c_textured & (c_uv < HELPER_DENSITY_RATIO * ref * np.maximum(c_area, 1e-12))
    drop = low[inv]
    if not drop.any() or drop.all():
        return np.zeros(len(F), bool)
    kept_vertices = np.unique(F[~drop])
    dominant = W.argmax(1)
    if not set(np.unique(dominant)) <= set(np.unique(dominant[kept_vertices])):
        return np.zeros(len(F), bool)  # the low-density part carries joints of its own: it is the body
    return drop

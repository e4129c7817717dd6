"""Which mesh pieces touch (numpy, no bpy): surface samples hashed into a voxel grid, so two
pieces touch when their surfaces come within about one cell, whatever their bounding boxes do
(a foot beside a tyre's box, a tube inside a tank).  Used by the rider removal and the split."""
import numpy as np

from .silhouette import surface_samples

_OFFS = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)], np.int64)


def _pack(cells):
    c = cells + (1 << 20)
    return (c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2]


class Touch:
    """P (n, 3) points, TW (m, 3) triangles, comps {key: Component}; cell in P's units.
    samples[key]: the piece's surface samples; touching(keys): the other keys whose surface
    lies in the group's cells or their 26 neighbours (within one to two cells)."""

    def __init__(self, P, TW, comps, cell):
        self.cell = cell
        self.cells, self.samples = {}, {}
        keys, owner = [], []
        for i, comp in comps.items():
            T = TW[comp.tris]
            used = np.unique(T)
            remap = np.full(len(P), -1)
            remap[used] = np.arange(len(used))
            X = surface_samples(P[used], remap[T], 0.5 * cell)
            self.samples[i] = X
            c = np.unique(np.floor(X / cell).astype(np.int64), axis=0)
            self.cells[i] = c
            keys.append(_pack(c))
            owner.append(np.full(len(c), i))
        self.keys = np.concatenate(keys) if keys else np.zeros(0, np.int64)
        self.owner = np.concatenate(owner) if owner else np.zeros(0, int)

    def touching(self, group):
        """Keys of the pieces whose surface is near any of `group`'s (the group excluded)."""
        if not group:
            return set()
        c = np.concatenate([self.cells[i] for i in group])
        near = np.unique(_pack((c[:, None, :] + _OFFS[None]).reshape(-1, 3)))
        return set(np.unique(self.owner[np.isin(self.keys, near)]).tolist()) - set(group)

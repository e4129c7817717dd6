"""A subset of surface samples that depends on the shape alone (numpy, no bpy).

The shape-based finders thin their surface samples to a fixed count.  A random choice of
indices depends on the order the samples come in, that is on the file's triangle order: a
model turned, re-exported or joined lists its triangles in another order and another random
subset is kept, which moved a dense bicycle's steer_top 4-10 cm.  Here every sample gets a
pseudo-random key from its own canonical position (quantised to CELL, the lateral coordinate
by its magnitude so a mirror image keeps the mirrored points) and the samples with the smallest
keys are kept: the same count, the same uniform thinning as a random subset, but the same
points whatever the order, the turn, the mirror or the file's unit once the pose has put the
model into the canonical frame (the frames of a turned copy agree to ~0.01 mm; a point flips
only within that of a cell wall)."""
import numpy as np

CELL = 0.002          # metres: well above the canonical frames' disagreement, below the finders' 1 cm
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def _mix(h):
    """splitmix64's finaliser (uint64 arrays; the products wrap, as the hash wants)."""
    h = h ^ (h >> np.uint64(30))
    h = h * _M1
    h = h ^ (h >> np.uint64(27))
    h = h * _M2
    return h ^ (h >> np.uint64(31))


def keys(X, cell=CELL):
    """(n,) uint64 pseudo-random key of each canonical point (x along, y up, z lateral)."""
    q = np.floor(np.column_stack([X[:, 0], X[:, 1], np.abs(X[:, 2])]) / cell).astype(np.int64).view(np.uint64)
    with np.errstate(over="ignore"):
        return _mix(q[:, 0] + _mix(q[:, 1] + _mix(q[:, 2] + np.uint64(0x9E3779B97F4A7C15))))


def thin(X, max_points, cell=CELL):
    """X's rows with the max_points smallest keys (in X's order; every row when there are fewer;
    rows sharing the cut-off key all kept, so the subset never depends on X's order)."""
    if len(X) <= max_points:
        return X
    k = keys(X, cell)
    cut = np.partition(k, max_points - 1)[max_points - 1]
    return X[k <= cut]

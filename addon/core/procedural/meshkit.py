"""Mesh primitives in numpy (canonical frame, metres): tubes, revolved profiles, boxes, lofts.

Pure numpy so the geometry can be built and tested without Blender; build.py turns a
MeshBuilder into one Blender mesh per part (Blender's frame conversion happens there).
"""
import numpy as np


class MeshBuilder:
    """Accumulates pieces of one part: vertices, polygons, a material name and smooth flag per face."""

    def __init__(self):
        self._verts = []
        self._faces = []  # lists of index tuples (tris, quads, n-gons)
        self._mats = []
        self._smooth = []
        self._tags = []  # per face: the sub-part it belongs to (None: the part itself)
        self._tag = None
        self._n = 0

    class _Tagged:
        def __init__(self, mb, tag):
            self.mb, self.tag = mb, tag

        def __enter__(self):
            self.prev, self.mb._tag = self.mb._tag, self.tag
            return self.mb

        def __exit__(self, *exc):
            self.mb._tag = self.prev

    def tagged(self, tag):
        """`with mb.tagged("rear_wheel"): ...`: the faces added inside belong to that sub-part
        (split off by split_tags), so a wheel can be its own mesh without changing its geometry."""
        return MeshBuilder._Tagged(self, tag)

    def add(self, verts, faces, material, smooth=True):
        verts = np.asarray(verts, dtype=float).reshape(-1, 3)
        off = self._n
        self._verts.append(verts)
        self._faces.extend(tuple(int(i) + off for i in f) for f in faces)
        self._mats.extend([material] * len(faces))
        self._smooth.extend([bool(smooth)] * len(faces))
        self._tags.extend([self._tag] * len(faces))
        self._n += len(verts)
        return self

    def split_tags(self):
        """-> (the untagged faces as a MeshBuilder, {tag: MeshBuilder}); vertices are kept only
        where a face of that builder uses them."""
        V = self.vertices
        groups = {}
        for f, m, sm, t in zip(self._faces, self._mats, self._smooth, self._tags):
            groups.setdefault(t, []).append((f, m, sm))
        out = {}
        for t, faces in groups.items():
            used = sorted({i for f, _, _ in faces for i in f})
            remap = {v: k for k, v in enumerate(used)}
            mb = MeshBuilder()
            mb._verts, mb._n = [V[used]], len(used)
            mb._faces = [tuple(remap[i] for i in f) for f, _, _ in faces]
            mb._mats = [m for _, m, _ in faces]
            mb._smooth = [sm for _, _, sm in faces]
            mb._tags = [None] * len(faces)
            out[t] = mb
        return out.pop(None, MeshBuilder()), out

    @property
    def vertices(self):
        return np.concatenate(self._verts) if self._verts else np.zeros((0, 3))

    @property
    def faces(self):
        return list(self._faces)

    @property
    def materials(self):
        return list(self._mats)

    @property
    def smooth(self):
        return list(self._smooth)

    def triangle_count(self):
        return sum(len(f) - 2 for f in self._faces)


# ---------------------------------------------------------------- curves

def bezier(p0, p1, p2, p3=None, n=12):
    """Quadratic (3 points) or cubic (4 points) Bezier sampled at n points, ends included."""
    t = np.linspace(0.0, 1.0, n)[:, None]
    p0, p1, p2 = (np.asarray(p, float) for p in (p0, p1, p2))
    if p3 is None:
        return (1 - t) ** 2 * p0 + 2 * (1 - t) * t * p1 + t ** 2 * p2
    p3 = np.asarray(p3, float)
    return (1 - t) ** 3 * p0 + 3 * (1 - t) ** 2 * t * p1 + 3 * (1 - t) * t ** 2 * p2 + t ** 3 * p3


def catmull_rom(points, n_per_seg=6):
    """A smooth curve through all points (centripetal-free uniform Catmull-Rom)."""
    p = np.asarray(points, float)
    ext = np.vstack([2 * p[0] - p[1], p, 2 * p[-1] - p[-2]])
    out = []
    for i in range(len(p) - 1):
        a, b, c, d = ext[i:i + 4]
        t = np.linspace(0, 1, n_per_seg, endpoint=False)[:, None]
        out.append(0.5 * ((2 * b) + (-a + c) * t + (2 * a - 5 * b + 4 * c - d) * t ** 2
                          + (-a + 3 * b - 3 * c + d) * t ** 3))
    out.append(p[-1:])
    return np.vstack(out)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _perp(t):
    """Some unit vector perpendicular to t."""
    a = np.array([0.0, 0.0, 1.0]) if abs(t[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    return _unit(np.cross(t, a))


# ---------------------------------------------------------------- primitives

def tube(path, radius, sides=12, caps=True, closed=False, squash=1.0, up=None):
    """Sweep a circle along a polyline (parallel-transport frames). Returns (verts, faces).

    radius: scalar or one per path point; squash scales the cross-section along the frame's
    second axis (an oval tube, e.g. a crank arm); up fixes that axis' start direction.
    """
    path = np.asarray(path, float)
    n = len(path)
    r = np.broadcast_to(np.asarray(radius, float), (n,))
    tang = np.gradient(path, axis=0) if n > 2 else np.repeat([path[1] - path[0]], n, axis=0)
    if closed:
        tang = np.roll(path, -1, axis=0) - np.roll(path, 1, axis=0)
    tang = tang / np.linalg.norm(tang, axis=1, keepdims=True)
    if up is not None:
        nrm = _unit(np.cross(np.cross(tang[0], up), tang[0]))
    else:
        nrm = _perp(tang[0])
    frames = []
    for i in range(n):
        if i > 0:  # transport the normal: remove its component along the new tangent
            nrm = nrm - tang[i] * np.dot(nrm, tang[i])
            nrm = _unit(nrm)
        frames.append((nrm, np.cross(tang[i], nrm)))
    ang = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ca, sa = np.cos(ang), np.sin(ang) * squash
    verts = np.empty((n, sides, 3))
    for i, (a, b) in enumerate(frames):
        verts[i] = path[i] + r[i] * (ca[:, None] * b + sa[:, None] * a)
    verts = verts.reshape(-1, 3)
    faces = []
    rings = n if closed else n - 1
    for i in range(rings):
        i2 = (i + 1) % n
        for j in range(sides):
            j2 = (j + 1) % sides
            faces.append((i * sides + j, i * sides + j2, i2 * sides + j2, i2 * sides + j))
    if caps and not closed:
        faces.append(tuple(range(sides))[::-1])
        faces.append(tuple((n - 1) * sides + j for j in range(sides)))
    return verts, faces


def cylinder(p0, p1, radius, sides=12, caps=True):
    return tube([p0, p1], radius, sides=sides, caps=caps)


def revolve(profile, segments, centre=(0, 0, 0), start=0.0, stop=2 * np.pi, closed_profile=True):
    """Revolve a profile of (r, z) points about the canonical Z axis through `centre`.

    The revolution is in the canonical X-Y plane (a wheel's plane); a full turn places a
    vertex at angle -90 deg (straight down) so a tyre's lowest point is exactly r_max below.
    """
    prof = np.asarray(profile, float)
    m = len(prof)
    full = np.isclose(stop - start, 2 * np.pi)
    if full:
        ang = -np.pi / 2 + np.linspace(0, 2 * np.pi, segments, endpoint=False)
        rings = segments
    else:
        ang = np.linspace(start, stop, segments)
        rings = segments - 1
    c = np.asarray(centre, float)
    verts = np.empty((len(ang), m, 3))
    verts[..., 0] = np.cos(ang)[:, None] * prof[None, :, 0]
    verts[..., 1] = np.sin(ang)[:, None] * prof[None, :, 0]
    verts[..., 2] = prof[None, :, 1]
    verts = verts.reshape(-1, 3) + c
    faces = []
    pm = m if closed_profile else m - 1
    for i in range(rings):
        i2 = (i + 1) % len(ang)
        for j in range(pm):
            j2 = (j + 1) % m
            faces.append((i * m + j, i2 * m + j, i2 * m + j2, i * m + j2))
    if not full and closed_profile:
        faces.append(tuple(range(m)))
        faces.append(tuple((len(ang) - 1) * m + j for j in range(m))[::-1])
    return verts, faces


def circle_profile(rc, zc, radius, n=12, sx=1.0, sz=1.0):
    """(r, z) points of a circle/ellipse, one of them at the outermost radius."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([rc + sx * radius * np.cos(a), zc + sz * radius * np.sin(a)], axis=1)


def box(centre, size, rot=None):
    """An oriented box: size (sx, sy, sz) along the columns of rot (default canonical axes)."""
    s = np.asarray(size, float) / 2
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * s
    if rot is not None:
        corners = corners @ np.asarray(rot, float).T
    verts = corners + np.asarray(centre, float)
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return verts, faces


def loft(rings, caps=True):
    """Connect rings (K, M, 3) of equal size into a closed-section surface with end caps."""
    rings = np.asarray(rings, float)
    k, m, _ = rings.shape
    verts = rings.reshape(-1, 3)
    faces = []
    for i in range(k - 1):
        for j in range(m):
            j2 = (j + 1) % m
            faces.append((i * m + j, i * m + j2, (i + 1) * m + j2, (i + 1) * m + j))
    if caps:
        faces.append(tuple(range(m))[::-1])
        faces.append(tuple((k - 1) * m + j for j in range(m)))
    return verts, faces


def ellipsoid(centre, radii, rot=None, seg=16, rings=10):
    """A UV ellipsoid with semi-axes radii (along rot's columns)."""
    th = np.linspace(0, np.pi, rings + 1)[1:-1]
    ph = np.linspace(0, 2 * np.pi, seg, endpoint=False)
    pts = [np.array([[0, 0, -1.0]])]
    for t in th:
        pts.append(np.stack([np.sin(t) * np.cos(ph), np.sin(t) * np.sin(ph), -np.cos(t) * np.ones_like(ph)], 1))
    pts.append(np.array([[0, 0, 1.0]]))
    v = np.vstack(pts) * np.asarray(radii, float)
    if rot is not None:
        v = v @ np.asarray(rot, float).T
    v = v + np.asarray(centre, float)
    faces = []
    nr = len(th)
    for j in range(seg):
        faces.append((0, 1 + (j + 1) % seg, 1 + j))
    for i in range(nr - 1):
        a, b = 1 + i * seg, 1 + (i + 1) * seg
        for j in range(seg):
            j2 = (j + 1) % seg
            faces.append((a + j, a + j2, b + j2, b + j))
    top = len(v) - 1
    a = 1 + (nr - 1) * seg
    for j in range(seg):
        faces.append((a + j, a + (j + 1) % seg, top))
    return v, faces


def extrude_annulus(outer, inner, z0, z1, centre=(0, 0, 0)):
    """A flat ring between two closed 2D outlines (same point count) in the X-Y plane, z0..z1."""
    outer = np.asarray(outer, float)
    inner = np.asarray(inner, float)
    m = len(outer)
    c = np.asarray(centre, float)
    layers = []
    for z in (z0, z1):
        for ring in (outer, inner):
            layers.append(np.column_stack([ring, np.full(m, z)]) + c)
    verts = np.vstack(layers)  # 0: outer z0, 1: inner z0, 2: outer z1, 3: inner z1
    faces = []
    o0, i0, o1, i1 = 0, m, 2 * m, 3 * m
    for j in range(m):
        j2 = (j + 1) % m
        faces.append((o0 + j, i0 + j, i0 + j2, o0 + j2))   # bottom face
        faces.append((o1 + j, o1 + j2, i1 + j2, i1 + j))   # top face
        faces.append((o0 + j, o0 + j2, o1 + j2, o1 + j))   # outer wall
        faces.append((i0 + j, i1 + j, i1 + j2, i0 + j2))   # inner wall
    return verts, faces


def rot_z(deg):
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1.0]])


def frame_from_x(x_dir, y_hint=(0, 1, 0)):
    """Rotation whose first column is x_dir, second the part of y_hint perpendicular to it."""
    x = _unit(x_dir)
    y = np.asarray(y_hint, float)
    y = _unit(y - x * np.dot(x, y))
    return np.column_stack([x, y, np.cross(x, y)])

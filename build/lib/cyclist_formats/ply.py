""".ply files (docs/contract.md "PLY"): 3DGS Gaussians in the INRIA layout, point clouds and
vertex-coloured triangle meshes.

Parsed with numpy here rather than plyfile because Blender 3.4's bundled Python has numpy but not
plyfile, and both worlds must read the same files the same way (the tests cross-check against
plyfile).  Binary little/big-endian and ASCII; list properties (faces) with a constant count.
"""
import os

import numpy as np

from .atomic import atomic_path
from .errors import UserError

_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
          "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
          "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint",
          "f4": "float", "f8": "double"}
_MAX_HEADER = 64 * 1024
# the fields every INRIA 3DGS .ply has (f_rest_* and normals are optional)
GAUSSIAN_FIELDS = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                   "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")


def _header(path, what):
    if not os.path.isfile(path):
        raise UserError(f"no such {what} file: {path}")
    with open(path, "rb") as f:
        head = f.read(_MAX_HEADER)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise UserError(f"{path} is not a .ply file")
    nl = head.find(b"\n", end)
    if nl < 0:
        raise UserError(f"{path}: truncated .ply header")
    fmt, elements = None, []  # [name, count, [(prop, type)], list spec (count type, item type) or None]
    for line in head[:end].decode("ascii", "replace").replace("\r", "").split("\n")[1:]:
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format":
            fmt = tok[1] if len(tok) > 1 else ""
            if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
                raise UserError(f"{path}: unknown .ply format '{' '.join(tok[1:])}'")
        elif tok[0] == "element":
            try:
                elements.append([tok[1], int(tok[2]), [], None])
            except (IndexError, ValueError):
                raise UserError(f"{path}: bad element line '{line.strip()}'") from None
            if elements[-1][1] < 0:
                raise UserError(f"{path}: negative count in '{line.strip()}'")
        elif tok[0] == "property" and elements:
            if len(tok) == 5 and tok[1] == "list" and tok[2] in _TYPES and tok[3] in _TYPES:
                elements[-1][3] = (tok[4], _TYPES[tok[2]], _TYPES[tok[3]])
            elif len(tok) == 3 and tok[1] in _TYPES:
                elements[-1][2].append((tok[2], _TYPES[tok[1]]))
            else:
                raise UserError(f"{path}: unsupported property '{line.strip()}'")
        else:
            raise UserError(f"{path}: unexpected header line '{line.strip()}'")
    if fmt is None:
        raise UserError(f"{path}: .ply header has no format line")
    return fmt, elements, nl + 1


def read_ply(path, what="ply", require_format=None):
    """.ply -> {element name: structured array}; a list property becomes field `name` of shape (k,)
    (every row must have the same count k, e.g. triangles).  UserError for anything malformed, or
    for a format other than require_format when given."""
    path = os.fspath(path)
    fmt, elements, start = _header(path, what)
    if require_format is not None and fmt != require_format:
        raise UserError(f"{path}: format '{fmt}' is not {require_format} (the {what} layout)")
    with open(path, "rb") as f:
        f.seek(start)
        body = f.read()
    out = {}
    if fmt == "ascii":
        rows = [line.split() for line in body.decode("ascii", "replace").split("\n") if line.strip()]
        r = 0
        for name, count, props, lst in elements:
            vals = rows[r:r + count]
            r += count
            if len(vals) < count:
                raise UserError(f"{path}: element '{name}' holds {len(vals)} of {count} rows (truncated)")
            try:
                if lst is None:
                    arr = np.zeros(count, dtype=[(p, "<" + t) for p, t in props])
                    table = np.array([v[:len(props)] for v in vals], dtype=np.float64).reshape(count, len(props))
                    for j, (p, _) in enumerate(props):
                        arr[p] = table[:, j]
                else:
                    k = int(vals[0][0]) if vals else 0
                    if any(int(v[0]) != k for v in vals):
                        raise UserError(f"{path}: '{name}' lists of different lengths are not supported")
                    arr = np.zeros(count, dtype=[(lst[0], "<" + lst[2], (k,))])
                    arr[lst[0]] = np.array([v[1:1 + k] for v in vals], dtype=np.float64).reshape(count, k)
            except ValueError as e:
                raise UserError(f"{path}: bad ASCII data in '{name}': {e}") from None
            out[name] = arr
        return out
    order = "<" if fmt == "binary_little_endian" else ">"
    off = 0
    for name, count, props, lst in elements:
        if lst is None:
            dt = np.dtype([(p, order + t) for p, t in props])
        else:
            if props:
                raise UserError(f"{path}: element '{name}' mixes list and scalar properties")
            ct = np.dtype(order + lst[1])
            k = int(np.frombuffer(body, dtype=ct, count=1, offset=off)[0]) if count and len(body) >= off + ct.itemsize else 0
            dt = np.dtype([("_n", ct), (lst[0], order + lst[2], (k,))])
        need = dt.itemsize * count
        if len(body) < off + need:
            got = (len(body) - off) // max(dt.itemsize, 1)
            raise UserError(f"{path}: element '{name}' holds {max(got, 0)} of {count} rows (truncated)")
        arr = np.frombuffer(body, dtype=dt, count=count, offset=off)
        off += need
        if lst is not None:
            if count and (arr["_n"] != k).any():
                raise UserError(f"{path}: '{name}' lists of different lengths are not supported")
            arr = arr[[lst[0]]]
        out[name] = arr
    return out


def _vertex(path, what, require_format=None):
    els = read_ply(path, what, require_format)
    if "vertex" not in els:
        raise UserError(f"{path}: no 'vertex' element")
    return els


def read_gaussians(path):
    """A 3DGS .ply -> structured array (N,) of its vertex fields; UserError unless it is binary
    little-endian (the INRIA layout) with exactly one `vertex` element with the INRIA fields, all finite."""
    els = _vertex(path, "Gaussian", "binary_little_endian")
    if list(els) != ["vertex"]:
        raise UserError(f"{path}: expected one 'vertex' element, found {list(els)}")
    v = els["vertex"]
    names = v.dtype.names
    missing = [k for k in GAUSSIAN_FIELDS if k not in names]
    if missing:
        raise UserError(f"{path} is not a 3DGS .ply: missing fields {', '.join(missing)}")
    for n in names:
        if v[n].dtype.kind == "f" and not np.isfinite(v[n]).all():
            raise UserError(f"{path}: non-finite values in '{n}'")
    return v


def _colors(v):
    names = v.dtype.names
    for keys in (("red", "green", "blue"), ("r", "g", "b")):
        if all(k in names for k in keys):
            c = np.stack([v[k] for k in keys], 1).astype(np.float64)
            return c / 255.0 if v[keys[0]].dtype.kind in "ui" or c.max() > 1.0 else c
    return None


def read_points(path):
    """A point cloud .ply -> (xyz (P, 3) float64, colours (P, 3) in [0, 1] or None)."""
    v = _vertex(path, "point cloud")["vertex"]
    if not all(k in v.dtype.names for k in "xyz"):
        raise UserError(f"{path}: vertex element has no x, y, z")
    xyz = np.stack([v["x"], v["y"], v["z"]], 1).astype(np.float64)
    if not np.isfinite(xyz).all():
        raise UserError(f"{path}: non-finite point coordinates")
    return xyz, _colors(v)


def read_colored_mesh(path):
    """A triangle .ply -> vertices (V, 3), faces (F, 3) int64, colours (V, 3) in [0, 1] (white if none)."""
    els = _vertex(path, "mesh")
    if "face" not in els:
        raise UserError(f"{path}: needs 'vertex' and 'face' elements")
    v, fa = els["vertex"], els["face"]
    faces = fa[fa.dtype.names[0]].astype(np.int64)
    if faces.ndim != 2 or (len(faces) and faces.shape[1] != 3):
        raise UserError(f"{path}: faces must be triangles")
    faces = faces.reshape(-1, 3)
    xyz = np.stack([v[k] for k in ("x", "y", "z")], 1).astype(np.float64)
    if not np.isfinite(xyz).all():
        raise UserError(f"{path}: non-finite vertex coordinates")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(xyz)):
        raise UserError(f"{path}: face indices out of range")
    c = _colors(v)
    return xyz, faces, np.ones_like(xyz) if c is None else c


def write_ply(path, vertex, faces=None):
    """Write a structured array as the `vertex` element (+ optional (F, 3) triangles), binary
    little-endian, atomically."""
    vertex = np.ascontiguousarray(vertex)
    fields = [(n, vertex.dtype.fields[n][0]) for n in vertex.dtype.names]
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertex)}"]
    header += [f"property {_NAMES[dt.str[1:]]} {n}" for n, dt in fields]
    le = vertex.astype([(n, "<" + dt.str[1:]) for n, dt in fields])
    body = [le.tobytes()]
    if faces is not None:
        faces = np.asarray(faces, dtype="<i4").reshape(-1, 3)
        header += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
        fa = np.zeros(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
        fa["n"], fa["v"] = 3, faces
        body.append(fa.tobytes())
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(("\n".join(header) + "\nend_header\n").encode("ascii"))
            for b in body:
                f.write(b)


def write_points(path, pts, normals=None, rgb=None):
    """xyz (+ normals, + uchar colour) point cloud, binary little-endian (readable by plyfile/trimesh)."""
    pts = np.asarray(pts)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if rgb is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    arr = np.zeros(len(pts), dtype=fields)
    for i, k in enumerate("xyz"):
        arr[k] = pts[:, i]
        if normals is not None:
            arr["n" + k] = np.asarray(normals)[:, i]
    if rgb is not None:
        for i, k in enumerate(("red", "green", "blue")):
            arr[k] = np.asarray(rgb)[:, i]
    write_ply(path, arr)

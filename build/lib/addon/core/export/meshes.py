"""A part's triangles with per-triangle materials (numpy only), and the OBJ/MTL writer."""
from dataclasses import dataclass, field

import numpy as np


@dataclass
class PartMesh:
    name: str
    verts: np.ndarray  # (N, 3) float64, canonical frame, rest pose
    tris: np.ndarray  # (T, 3) int64
    mat: np.ndarray  # (T,) int64 index into materials
    materials: list = field(default_factory=list)  # [(name, (r, g, b, a) linear, metallic, roughness)]

    def area_weighted_colour(self):
        """Mean linear RGBA over the surface (one colour for formats that take one per link)."""
        if not self.materials:
            return (0.8, 0.8, 0.8, 1.0)
        a, b, c = (self.verts[self.tris[:, k]] for k in range(3))
        area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        w = np.bincount(self.mat, weights=area, minlength=len(self.materials))
        cols = np.array([m[1] for m in self.materials], float)
        return tuple(float(x) for x in (w @ cols) / max(w.sum(), 1e-30))


def _name(s):
    return "".join(ch if ch.isalnum() or ch in "_-." else "_" for ch in s) or "material"


def write_obj(f_obj, f_mtl, mtl_name, verts, mesh):
    """OBJ (vertices `verts`, faces of `mesh`, one usemtl group per material) + its MTL (Kd = colour)."""
    f_mtl.write("# diffuse colours of the part's Blender materials (linear RGB)\n")
    for name, rgba, *_ in mesh.materials or [("default", (0.8, 0.8, 0.8, 1.0))]:
        f_mtl.write(f"newmtl {_name(name)}\nKd {rgba[0]:.6f} {rgba[1]:.6f} {rgba[2]:.6f}\nd {rgba[3]:.6f}\n\n")
    f_obj.write(f"mtllib {mtl_name}\n")
    f_obj.write("".join(f"v {x:.7f} {y:.7f} {z:.7f}\n" for x, y, z in verts))
    names = [_name(m[0]) for m in mesh.materials] or ["default"]
    for k in np.unique(mesh.mat) if len(mesh.tris) else []:
        f_obj.write(f"usemtl {names[k]}\n")
        t = mesh.tris[mesh.mat == k] + 1
        f_obj.write("".join(f"f {a} {b} {c}\n" for a, b, c in t))

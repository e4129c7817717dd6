"""Cut the faces of a fused piece along the part boundaries (bmesh bisect), so a frame, steering and
crank made from one mesh come out as clean rigid pieces."""
import bmesh
import numpy as np

from ..frames import C as C_BL
from ..frames import to_canonical
from . import split
from .scene_state import CUT_ATTR, PART_ATTR


def cut_fused_faces(obj, kp, split_args, rounds=3):
    """Cut the faces flagged CUT_ATTR (a fused piece lying across parts) along split.cut_planes
    (bmesh bisect: UVs and materials are interpolated onto the new faces), then label each face
    by the region at its centre, so the frame, steering and crank made from a single fused mesh
    are clean rigid pieces rather than faces labelled by their centroid.  Only faces whose
    corners lie in different regions are cut, and only by the planes that cross them.
    obj: curation_source in the canonical pose (Blender frame).  Returns the faces added."""
    planes = [(p @ C_BL.T, n @ C_BL.T) for p, n in split.cut_planes(kp, split_args.get("head_radius"),
                                                                    split_args.get("wheel_radius"),
                                                                    split_args.get("head_span"))]

    def reg(pts_bl):
        return split.regions(to_canonical(np.asarray(pts_bl, float).reshape(-1, 3)), kp, split_args.get("head_radius"),
                             split_args.get("wheel_radius"), split_args.get("head_span"))

    bm = bmesh.new()
    bm.from_mesh(obj.data)
    n0 = len(bm.faces)
    cut_l = bm.faces.layers.int.get(CUT_ATTR)
    part_l = bm.faces.layers.int.get(PART_ATTR)
    for _ in range(rounds):
        flagged = [f for f in bm.faces if f[cut_l]]
        if not flagged:
            break
        # corners, edge midpoints and centre: a long face can cross a region with its corners outside
        corners = []
        for f in flagged:
            cs = [np.array(v.co[:]) for v in f.verts]
            corners.append(cs + [0.5 * (cs[j] + cs[j - 1]) for j in range(len(cs))] + [sum(cs) / len(cs)])
        labs = reg([c for cs in corners for c in cs])
        mixed, i = set(), 0
        for f, cs in zip(flagged, corners):
            if len(set(labs[i:i + len(cs)].tolist())) > 1:
                mixed.add(f)
            i += len(cs)
        if not mixed:
            break
        for co, no in planes:
            hit = [f for f in mixed if f.is_valid and _straddles(f, co, no)]
            if not hit:
                continue
            edges = list({e for f in hit for e in f.edges})
            verts = list({v for f in hit for v in f.verts})
            ret = bmesh.ops.bisect_plane(bm, geom=hit + edges + verts, dist=1e-6, plane_co=co.tolist(),
                                         plane_no=no.tolist())
            mixed = {f for f in mixed if f.is_valid} | {g for g in ret["geom"] if isinstance(g, bmesh.types.BMFace)}
    flagged = [f for f in bm.faces if f[cut_l]]
    if flagged:
        lab = reg([f.calc_center_median()[:] for f in flagged])
        if not split_args.get("has_crank", True):
            lab[lab == split.CRANK] = split.FRAME
        for f, k in zip(flagged, lab.tolist()):
            f[part_l] = k
    added = len(bm.faces) - n0
    bm.to_mesh(obj.data)
    bm.free()
    obj.data.update()
    return added


def _straddles(face, co, no, eps=1e-6):
    d = [(v.co[0] - co[0]) * no[0] + (v.co[1] - co[1]) * no[1] + (v.co[2] - co[2]) * no[2] for v in face.verts]
    return min(d) < -eps and max(d) > eps

"""Rider body model: an `anny` human in an SMPL-like T-pose, reduced to the 24 SMPL joints.

anny (Apache-2.0 code, CC0 MakeHuman assets) builds its model data once (~80-100 s) and caches
it; we point its cache at `data/anny_cache/` (git-ignored) unless ANNY_CACHE_DIR is set.

Pipeline of `build_rider` (splatting.rider.roster.load_rider picks the body model):
1. anny forward pass with the roster's phenotype (identity pose deltas).
2. T-pose with anny's own 104-bone skinning: arms straight out sideways, legs straight down,
   so the rest pose matches SMPL's zero pose and SMPL axis-angle poses drive it directly.
3. anny frame -> canonical frame. anny is Z up, the body faces -Y, its left side is +X; the
   canonical frame is X forward, Y up, Z to the body's right:
   (X, Y, Z)_canonical = (-y, z, -x)_anny  (a proper rotation, det +1).
   Then shifted so the soles touch Y = 0 and the pelvis joint has X = Z = 0.
4. The 104 anny bones are mapped onto the 24 SMPL joints (ANNY_TO_SMPL): a joint sits at its
   bone's head (or the mean of several heads); every bone's skinning weight goes to the nearest
   mapped ancestor-or-self, so each vertex keeps weights summing to 1 over the 24 joints.
"""
import dataclasses
import functools
import os
from pathlib import Path

import numpy as np
import roma
import torch

from cyclist_formats.atomic import atomic_path
from cyclist_formats.errors import UserError
from splatting import paths
from splatting.rider.kinematics import JOINT_INDEX, JOINT_NAMES, forward_kinematics
from splatting.rider.looks import dress, hex_rgb, look_of, validate_look

CACHE_DIR = paths.DATA / "anny_cache"
ROOT = paths.ROOT

# anny -> canonical rotation (see module docstring).
ANNY_TO_CANONICAL = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])

# SMPL joint -> anny bone(s) whose head(s) give its position. The spine split follows the
# heights of SMPL's joints above the pelvis (spine1 ~12 cm, spine2 ~25, spine3 ~31, neck ~52).
ANNY_TO_SMPL = {
    "pelvis": ["root"],
    "left_hip": ["upperleg01.L"], "right_hip": ["upperleg01.R"],
    "spine1": ["spine03"],
    "left_knee": ["lowerleg01.L"], "right_knee": ["lowerleg01.R"],
    "spine2": ["spine02"],
    "left_ankle": ["foot.L"], "right_ankle": ["foot.R"],
    "spine3": ["spine01"],
    "left_foot": [f"toe{i}-1.L" for i in range(1, 6)],
    "right_foot": [f"toe{i}-1.R" for i in range(1, 6)],
    "neck": ["neck01"],
    "left_collar": ["clavicle.L"], "right_collar": ["clavicle.R"],
    "head": ["head"],
    "left_shoulder": ["upperarm01.L"], "right_shoulder": ["upperarm01.R"],
    "left_elbow": ["lowerarm01.L"], "right_elbow": ["lowerarm01.R"],
    "left_wrist": ["wrist.L"], "right_wrist": ["wrist.R"],
    # SMPL's hand joint sits at the knuckles: the fingers' first heads (the palm stays on the wrist).
    "left_hand": [f"finger{i}-1.L" for i in range(2, 6)],
    "right_hand": [f"finger{i}-1.R" for i in range(2, 6)],
}
# Bones that skin onto a joint other than their nearest mapped ancestor.
_WEIGHT_OVERRIDES = {f"finger1-{k}.{s}": f"{side}_hand" for k in (1, 2, 3)
                     for s, side in (("L", "left"), ("R", "right"))}

# T-pose targets (anny frame): bone -> (segment end bone, direction). Rotating a bone turns its
# whole subtree about its head; chains are straightened parent first.
_TPOSE_PASSES = [
    {"upperarm01.L": ("lowerarm01.L", (1, 0, 0)), "upperarm01.R": ("lowerarm01.R", (-1, 0, 0)),
     "upperleg01.L": ("lowerleg01.L", (0, 0, -1)), "upperleg01.R": ("lowerleg01.R", (0, 0, -1))},
    {"lowerarm01.L": ("wrist.L", (1, 0, 0)), "lowerarm01.R": ("wrist.R", (-1, 0, 0)),
     "lowerleg01.L": ("foot.L", (0, 0, -1)), "lowerleg01.R": ("foot.R", (0, 0, -1))},
    {"wrist.L": ("finger3-1.L", (1, 0, 0)), "wrist.R": ("finger3-1.R", (-1, 0, 0))},
]


@dataclasses.dataclass
class Rider:
    """A rider in the canonical T-pose (metres, soles on Y = 0, facing +X, pelvis at X = Z = 0)."""
    id: str
    vertices: torch.Tensor  # (V, 3) float32
    faces: torch.Tensor  # (F, 3) int64
    joints: torch.Tensor  # (24, 3) float32, SMPL order
    weights: torch.Tensor  # (V, 24) float32, rows sum to 1
    colors: torch.Tensor  # (V, 3) float32 in [0, 1]
    height_m: float
    spec: dict
    regions: torch.Tensor = None  # (V,) int64 clothing region per vertex (REGIONS), None if unknown
    # vertices [0, body_vertex_count) are the body's own (keypoint regressors pick among them); the
    # rest are accessories (helmet, hair, backpack: looks.py).  None: all are the body's.
    body_vertex_count: int = None
    # what `dress` started from (the anny path; None for SMPL and imported bodies): the body's own
    # vertices, faces, weights, joints and eye centres, float64 as dressed, so `redress` can put the
    # same body into another look (per-instance accessories, splatting/cyclist/accessories.py)
    undressed: dict = None
    # the appended accessories' vertex ranges, {name: (first, last + 1)} (looks.dress's parts)
    accessory_parts: dict = None


def _cache_dir():
    return Path(os.environ.get("ANNY_CACHE_DIR", CACHE_DIR))


@functools.lru_cache(maxsize=1)
def anny_model():
    """The anny full-body model (built once into the cache, ~3 s to load afterwards)."""
    try:
        import anny
        from anny.paths import set_anny_cache_path
    except ImportError as e:  # pragma: no cover - environment problem
        raise UserError(f"the rider body model needs the 'anny' package ({e})") from e
    cache = _cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    set_anny_cache_path(cache)
    # Plain torch LBS: avoids warp's kernel compile for the few forward passes we make.
    return anny.Anny(skinning_method="lbs")


def _swing(a, b):
    """Smallest rotation (3,3) turning unit vector a onto unit vector b (float64 numpy)."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.dot(a, b))
    if s < 1e-12:
        return np.eye(3)
    rv = axis / s * np.arctan2(s, c)
    return roma.rotvec_to_rotmat(torch.from_numpy(rv)).numpy()


def _anny_tpose(model, phenotype):
    """Posed (T-pose) vertices (V,3) and bone heads (104,3) in anny's frame, float64."""
    labels = list(model.bone_labels)
    idx = {n: i for i, n in enumerate(labels)}
    parents = list(model.bone_parents)
    U = model.reference_bone_orientations.double()
    deltas = torch.eye(4, dtype=torch.float64).repeat(1, len(labels), 1, 1)

    def run():
        with torch.no_grad():
            return model(pose_parameters=deltas, phenotype_kwargs=dict(phenotype))

    out = run()
    for targets in _TPOSE_PASSES:
        W = out["bone_poses"][0].double()
        heads = W[:, :3, 3].numpy()
        G = (W[:, :3, :3] @ U.transpose(-1, -2)).numpy()  # world rotation gained by each bone
        for bone, (end, direction) in targets.items():
            b, e = idx[bone], idx[end]
            cur = heads[e] - heads[b]
            cur = cur / np.linalg.norm(cur)
            want = np.asarray(direction, float)
            E = _swing(cur, want)
            Gp = G[parents[b]]
            # local-ref deltas compose as G_c = G_p D_c, so a world turn E needs D = Gp^T E Gp D.
            D = Gp.T @ E @ Gp @ deltas[0, b, :3, :3].numpy()
            deltas[0, b, :3, :3] = torch.from_numpy(D)
        out = run()
    return out["vertices"][0].double().numpy(), out["bone_poses"][0, :, :3, 3].double().numpy(), labels, parents


def _bone_to_joint(labels, parents):
    """For each anny bone, the SMPL joint index its skinning weight goes to."""
    head_of = {}
    for j, name in enumerate(JOINT_NAMES):
        for bone in ANNY_TO_SMPL[name]:
            head_of[bone] = j
    out = []
    for i, label in enumerate(labels):
        if label in _WEIGHT_OVERRIDES:
            out.append(JOINT_INDEX[_WEIGHT_OVERRIDES[label]])
            continue
        k = i
        while labels[k] not in head_of:
            k = parents[k]
        # metacarpals map to the wrist via the ancestor walk; finger bones to the hand via override
        # or their own heads in ANNY_TO_SMPL's hand lists.
        out.append(head_of[labels[k]])
    return np.array(out)


# clothing regions of a rider (index = the region id each vertex and avatar Gaussian carries)
REGIONS = ("skin", "top", "bottom", "shoes", "helmet", "hair", "bag")


def region_ids(verts, weights, joints, eye_y):
    """(V,) int64 region per vertex (REGIONS): shoes on feet, bottom on hips/thighs/knees and the
    lower pelvis, top on the torso and upper arms, helmet on the head above the brow, skin elsewhere."""
    J = JOINT_INDEX
    dom = weights.argmax(1)
    out = np.zeros(len(verts), np.int64)
    y = verts[:, 1]
    waist_y = joints[J["pelvis"], 1] + 0.6 * (joints[J["spine1"], 1] - joints[J["pelvis"], 1])
    shoes = np.isin(dom, [J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"]])
    legs = np.isin(dom, [J["left_hip"], J["right_hip"], J["left_knee"], J["right_knee"]])
    # Shorts end a little above the knee.
    knee_y = joints[J["left_knee"], 1]
    bottom = (legs & (y > knee_y + 0.06)) | ((dom == J["pelvis"]) & (y < waist_y))
    torso = np.isin(dom, [J["pelvis"], J["spine1"], J["spine2"], J["spine3"], J["left_collar"],
                          J["right_collar"], J["left_shoulder"], J["right_shoulder"]]) & ~bottom
    # Short sleeves: the upper arm's outer half stays skin.
    shoulder_z = abs(joints[J["left_shoulder"], 2])
    elbow_z = abs(joints[J["left_elbow"], 2])
    torso &= np.abs(verts[:, 2]) < shoulder_z + 0.5 * (elbow_z - shoulder_z)
    head_top = (dom == J["head"]) & (y > eye_y + 0.025)
    for name, m in (("shoes", shoes), ("bottom", bottom), ("top", torso), ("helmet", head_top)):
        out[m] = REGIONS.index(name)
    return out


def _region_colors(verts, weights, joints, eye_y, colors):
    """Per-vertex colours of the regions (region_ids) from the rider's '#rrggbb' colours."""
    # region_ids paints no hair or bag (only looks.py adds those), so they may have no colour here
    palette = np.stack([hex_rgb(colors.get(r, colors["skin"])) for r in REGIONS])
    return palette[region_ids(verts, weights, joints, eye_y)]


def build_rider(spec):
    """Rider from a roster entry (dict with 'id', 'phenotype', 'colors')."""
    model = anny_model()
    verts_a, heads_a, labels, parents = _anny_tpose(model, spec["phenotype"])
    verts = verts_a @ ANNY_TO_CANONICAL.T
    heads = heads_a @ ANNY_TO_CANONICAL.T
    idx = {n: i for i, n in enumerate(labels)}
    joints = np.stack([heads[[idx[b] for b in ANNY_TO_SMPL[n]]].mean(0) for n in JOINT_NAMES])
    shift = np.array([-joints[0, 0], -verts[:, 1].min(), -joints[0, 2]])
    verts, heads, joints = verts + shift, heads + shift, joints + shift

    b2j = _bone_to_joint(labels, parents)
    w = model.vertex_bone_weights.double().numpy()
    bi = model.vertex_bone_indices.numpy()
    weights = np.zeros((len(verts), len(JOINT_NAMES)))
    np.add.at(weights, (np.repeat(np.arange(len(verts)), bi.shape[1]), b2j[bi].ravel()), w.ravel())
    weights /= weights.sum(1, keepdims=True)

    eyes = heads[[idx["eye.L"], idx["eye.R"]]]
    height = float(verts[:, 1].max() - verts[:, 1].min())  # the body's, before any helmet or hair
    undressed = {"vertices": verts, "faces": model.faces.long().numpy(), "weights": weights, "joints": joints,
                 "eyes": eyes, "height_m": height}
    return _dressed(spec, undressed, look_of(spec))


def _dressed(spec, u, look):
    """The Rider of roster entry spec: the undressed body u (build_rider's) in the look."""
    eye_y = u["eyes"][:, 1].mean()
    verts, faces, weights, colors, regions, parts = dress(
        u["vertices"], u["faces"], u["weights"], u["joints"], eye_y, u["eyes"], spec["colors"],
        region_ids(u["vertices"], u["weights"], u["joints"], eye_y), look, REGIONS)
    f32 = lambda a: torch.from_numpy(np.ascontiguousarray(a)).float()
    return Rider(id=spec["id"], vertices=f32(verts), faces=torch.from_numpy(np.ascontiguousarray(faces)).long(),
                 joints=f32(u["joints"]), weights=f32(weights), colors=f32(colors), height_m=u["height_m"],
                 spec=dict(spec), regions=torch.from_numpy(np.ascontiguousarray(regions)),
                 body_vertex_count=len(u["vertices"]), undressed=u, accessory_parts=dict(parts))


def redress(rider, **look):
    """The same body in its look with some fields replaced (looks.LOOK_FIELDS: e.g. helmet=False,
    hair="bun", bag="backpack"): a new Rider whose first body_vertex_count vertices, faces and weights
    are the rider's own; its colours, regions and appended accessories are what `dress` makes of the
    new look, exactly as a roster entry with that `look:` block would be built."""
    if rider.undressed is None:
        raise UserError(f"rider {rider.id} ({rider.spec.get('body', 'anny')} body) has no roster look to change; "
                        f"per-instance accessories need an anny roster rider")
    bad = validate_look(look)
    if bad:
        raise UserError(bad)
    spec = dict(rider.spec, look=dict(rider.spec.get("look") or {}, **look))
    return _dressed(spec, rider.undressed, look_of(spec))


def pose_vertices(rider, local_rotmats, root_trans=None):
    """Linear blend skinning: (B,24,3,3) local rotations (+ (B,3) root translation) -> (B,V,3)."""
    if local_rotmats.dim() != 4 or local_rotmats.shape[1:] != (24, 3, 3):
        raise UserError(f"local_rotmats must be (B,24,3,3), got {tuple(local_rotmats.shape)}")
    dtype = local_rotmats.dtype
    _, T = forward_kinematics(rider.joints.to(dtype), local_rotmats, root_trans)
    A = torch.einsum("vj,bjkl->bvkl", rider.weights.to(dtype), T[:, :, :3, :])  # (B,V,3,4)
    v = rider.vertices.to(dtype)
    return (A[..., :3] @ v.unsqueeze(-1)).squeeze(-1) + A[..., 3]


def posed_joints(rider, local_rotmats, root_trans=None):
    """(B,24,3) joint positions for the pose (the same FK as pose_vertices)."""
    return forward_kinematics(rider.joints.to(local_rotmats.dtype), local_rotmats, root_trans)[0]


def export_mesh(path, vertices, faces, colors):
    """Write a vertex-coloured mesh (.ply or .obj, canonical frame) atomically."""
    import trimesh  # lazy: 0.7 s to import (python -X importtime), for the mesh export alone
    ext = os.path.splitext(str(path))[1].lower()
    if ext not in (".ply", ".obj"):
        raise UserError(f"mesh output must end in .ply or .obj, got {path}")
    v = np.asarray(vertices, dtype=np.float64)
    if not np.isfinite(v).all():
        raise UserError("mesh has non-finite vertices")
    rgba = np.concatenate([np.clip(np.asarray(colors) * 255 + 0.5, 0, 255),
                           np.full((len(v), 1), 255)], 1).astype(np.uint8)
    mesh = trimesh.Trimesh(v, np.asarray(faces), vertex_colors=rgba, process=False)
    with atomic_path(path) as tmp:
        mesh.export(tmp, file_type=ext[1:])
    return path


def export_rider(rider, path, vertices=None):
    """Export the rest mesh (or given posed (V,3) vertices) with the rider's vertex colours."""
    v = rider.vertices if vertices is None else vertices
    return export_mesh(path, torch.as_tensor(v).detach().cpu().numpy(), rider.faces.numpy(),
                       rider.colors.numpy())

"""User-supplied SMPL bodies (through the `smplx` package) as a body.Rider.

SMPL model files cannot be shipped; users who own them point `load_smpl_rider` (or a roster
entry with `body: smpl` and `model_path:`) at their SMPL_*.pkl / .npz. smplx builds the model
from the file; its own `lbs` at the zero pose gives the shaped rest vertices and the 24 joints
regressed by the model's J_regressor. The model's LBS weights and faces are used as they are.

Frame: SMPL is Y up, facing +Z, its left at +X. The canonical frame is that turned by
C = Ry(+90 deg) (motion.C_SMPL: (X, Y, Z) = (z, y, -x)_smpl), then shifted so the soles touch
Y = 0 and the pelvis joint has X = Z = 0 (as body.py). SMPL's zero pose already is the T-pose,
so an SMPL local rotation R drives this rider as C R C^T (motion.py's conversion) through
body.pose_vertices, reproducing smplx's skinning exactly except for the pose-corrective blend
shapes (posedirs), which a Rider has no place for (tests/test_smpl_body.py checks the rest).
"""
import contextlib
import io
import pickle
import zipfile
from pathlib import Path

import numpy as np
import torch

from cyclist_formats.errors import UserError
from splatting.rider.body import ROOT, Rider, _region_colors, region_ids
from splatting.rider.kinematics import JOINT_INDEX, PARENTS
from splatting.rider.motion import C_SMPL

REQUIRED_KEYS = ("v_template", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table", "f")
GENDERS = ("neutral", "female", "male")
DEFAULT_COLORS = {"skin": "#e0ac8a", "top": "#1f77b4", "bottom": "#222222", "shoes": "#f0f0f0",
                  "helmet": "#d62728"}
NOT_SHIPPED = "SMPL model files are not shipped; download them from https://smpl.is.tue.mpg.de"


def _smplx():
    try:
        import smplx
    except ImportError as e:  # pragma: no cover - environment problem
        raise UserError(f"SMPL bodies need the 'smplx' package ({e})") from e
    return smplx


def resolve_model_path(model_path, gender="neutral"):
    """The model file: `model_path` itself, or SMPL_<GENDER>.pkl/.npz inside a folder."""
    if gender not in GENDERS:
        raise UserError(f"SMPL gender must be one of {', '.join(GENDERS)}, got {gender!r}")
    path = Path(model_path).expanduser()
    if path.is_dir():
        for ext in (".pkl", ".npz"):
            candidate = path / f"SMPL_{gender.upper()}{ext}"
            if candidate.is_file():
                return candidate
        raise UserError(f"no SMPL_{gender.upper()}.pkl or .npz in {path} ({NOT_SHIPPED})")
    if not path.is_file():
        raise UserError(f"SMPL model file not found: {path} ({NOT_SHIPPED})")
    return path


def read_model_file(path):
    """The model's arrays as a dict (UserError if the file is not a usable SMPL model).

    A .pkl is unpickled the way smplx does (latin1; the user's own file, so trusted). The
    original SMPL 1.0 pickles hold chumpy arrays and a scipy sparse J_regressor: those need the
    'chumpy'/'scipy' packages to unpickle, which we do not install; a chumpy-free .pkl/.npz works."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        else:
            with open(path, "rb") as fh:
                data = pickle.load(fh, encoding="latin1")
    except ModuleNotFoundError as e:
        raise UserError(f"{path}: unpickling needs the '{e.name}' package; convert the model to a "
                        f"chumpy-free .npz (numpy arrays under the SMPL key names)") from None
    except (OSError, ValueError, EOFError, pickle.UnpicklingError, zipfile.BadZipFile,
            AttributeError, ImportError, IndexError, TypeError) as e:
        raise UserError(f"cannot read SMPL model {path}: {type(e).__name__}: {e}") from None
    if not isinstance(data, dict):
        raise UserError(f"{path}: not an SMPL model (expected a dict of arrays, got {type(data).__name__})")
    missing = [k for k in REQUIRED_KEYS if k not in data]
    if missing:
        raise UserError(f"{path}: not an SMPL model, missing {', '.join(missing)}")
    return data


def _check_structure(path, data):
    """Shapes an SMPL body needs here: 24 joints in SMPL's kinematic tree."""
    def shape(k):
        return tuple(np.shape(data[k]))
    v = shape("v_template")
    if len(v) != 2 or v[1] != 3:
        raise UserError(f"{path}: v_template must be (V,3), got {v}")
    n = v[0]
    want = {"weights": (n, 24), "J_regressor": (24, n), "kintree_table": (2, 24)}
    for k, s in want.items():
        if shape(k) != s:
            raise UserError(f"{path}: {k} must be {s} for a 24-joint SMPL body, got {shape(k)}")
    if len(shape("shapedirs")) != 3 or shape("shapedirs")[:2] != (n, 3):
        raise UserError(f"{path}: shapedirs must be ({n},3,K), got {shape('shapedirs')}")
    if shape("posedirs") != (n, 3, 207):
        raise UserError(f"{path}: posedirs must be ({n},3,207), got {shape('posedirs')}")
    f = np.asarray(data["f"])
    if f.ndim != 2 or f.shape[1] != 3 or f.size == 0 or f.min() < 0 or f.max() >= n:
        raise UserError(f"{path}: f must be (F,3) vertex indices below {n}")
    parents = np.asarray(data["kintree_table"])[0].astype(np.int64)
    if tuple(parents[1:]) != PARENTS[1:]:
        raise UserError(f"{path}: kintree_table is not SMPL's 24-joint tree")


def smpl_model(model_path, gender="neutral", num_betas=10, dtype=torch.float64, data=None):
    """A smplx.SMPL module for the user's model file (or folder + gender); `data` is the file's
    already-read dict, if at hand."""
    smplx = _smplx()
    path = resolve_model_path(model_path, gender)
    data = read_model_file(path) if data is None else data
    _check_structure(path, data)
    num_betas = min(int(num_betas), int(np.shape(data["shapedirs"])[2]))
    # smplx prints a warning for 10-component (SMPL 1.0) shape spaces; keep the CLI quiet.
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            return smplx.SMPL(str(path), data_struct=smplx.utils.Struct(**data), gender=gender,
                              num_betas=num_betas, dtype=dtype)
        except (ValueError, TypeError) as e:
            raise UserError(f"{path}: smplx cannot build an SMPL model from it: {e}") from None


def _betas(betas, n_max):
    if betas is None:
        return np.zeros(0)
    b = np.asarray(betas, dtype=np.float64).reshape(-1)
    if not np.isfinite(b).all():
        raise UserError("SMPL betas contain NaN or infinite values")
    if len(b) > n_max:
        raise UserError(f"{len(b)} SMPL betas given, the model has {n_max} shape components")
    return b


def _eye_height(verts, joints):
    """Eye level for the helmet line: halfway from the SMPL head joint (about ear level at the
    back of the skull) to the crown; SMPL has no eye joint."""
    return 0.5 * (joints[JOINT_INDEX["head"], 1] + verts[:, 1].max())


def load_smpl_rider(model_path, betas=None, gender="neutral", rider_id=None, colors=None):
    """Rider (canonical T-pose, see body.Rider) from a user's SMPL model file or folder.

    betas: up to the model's shape components (missing ones are 0); colors: dict with skin, top,
    bottom, shoes, helmet as '#rrggbb' (default DEFAULT_COLORS)."""
    smplx = _smplx()
    path = resolve_model_path(model_path, gender)
    data = read_model_file(path)
    _check_structure(path, data)
    b = _betas(betas, int(np.shape(data["shapedirs"])[2]))
    model = smpl_model(path, gender, num_betas=max(len(b), 1), data=data)
    betas_t = torch.zeros(1, model.num_betas, dtype=torch.float64)
    betas_t[0, :len(b)] = torch.from_numpy(b)
    with torch.no_grad():
        # Zero pose through smplx's own LBS: shaped template and J_regressor joints.
        verts, joints = smplx.lbs.lbs(betas_t, torch.zeros(1, 72, dtype=torch.float64),
                                      model.v_template, model.shapedirs, model.posedirs,
                                      model.J_regressor, model.parents, model.lbs_weights)
    verts = verts[0].numpy() @ C_SMPL.T
    joints = joints[0].numpy() @ C_SMPL.T
    shift = np.array([-joints[0, 0], -verts[:, 1].min(), -joints[0, 2]])
    verts, joints = verts + shift, joints + shift
    weights = model.lbs_weights.numpy()
    if not np.isfinite(verts).all() or not np.allclose(weights.sum(1), 1.0, atol=1e-4):
        raise UserError(f"{path}: SMPL model gives non-finite vertices or weights not summing to 1")
    cols = dict(DEFAULT_COLORS, **(colors or {}))
    try:
        eye_y = _eye_height(verts, joints)
        rgb = _region_colors(verts, weights, joints, eye_y, cols)
    except (ValueError, AttributeError) as e:
        raise UserError(f"SMPL rider colours must be '#rrggbb' strings: {e}") from None
    rid = rider_id or f"smpl_{gender}"
    spec = {"id": rid, "body": "smpl", "model_path": str(path), "gender": gender,
            "betas": b.tolist(), "colors": cols}
    f32 = lambda a: torch.from_numpy(np.ascontiguousarray(a)).float()
    return Rider(id=rid, vertices=f32(verts), faces=model.faces_tensor.long().clone(),
                 joints=f32(joints), weights=f32(weights), colors=f32(rgb),
                 height_m=float(verts[:, 1].max() - verts[:, 1].min()), spec=spec,
                 regions=torch.from_numpy(region_ids(verts, weights, joints, eye_y)))


def rider_from_spec(spec):
    """Rider for a roster entry with `body: smpl`: model_path (a relative path is taken from the
    repository root), optional gender, betas, colors."""
    model_path = spec.get("model_path")
    if not isinstance(model_path, str) or not model_path:
        raise UserError(f"rider {spec.get('id')!r}: 'body: smpl' needs a 'model_path' ({NOT_SHIPPED})")
    path = Path(model_path).expanduser()
    if not path.is_absolute():
        path = ROOT / path
    rider = load_smpl_rider(path, betas=spec.get("betas"), gender=spec.get("gender", "neutral"),
                            rider_id=spec.get("id"), colors=spec.get("colors"))
    rider.spec = dict(spec, **{k: rider.spec[k] for k in ("body", "model_path", "betas")})
    return rider


__all__ = ["load_smpl_rider", "rider_from_spec", "smpl_model", "read_model_file",
           "resolve_model_path", "DEFAULT_COLORS"]

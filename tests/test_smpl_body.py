"""User-supplied SMPL models through smplx (splatting/rider/smpl_body.py).

SMPL files cannot be shipped, so every test writes a randomly generated model with SMPL's
structure (24 joints, SMPL's kinematic tree, the keys smplx reads): a stick figure of small
octahedra around plausible SMPL joint positions, each vertex skinned to its joint and parent.
"""
import pickle

import numpy as np
import pytest
import torch

smplx = pytest.importorskip("smplx")

from cyclist_formats.errors import UserError  # noqa: E402
from splatting.rider.kinematics import JOINT_INDEX, PARENTS  # noqa: E402
from splatting.rotations import axis_angle_to_rotmat, rodrigues  # noqa: E402

J = JOINT_INDEX
# SMPL frame (Y up, facing +Z, left at +X), origin ~1.15 m above the soles like SMPL's template.
SMPL_JOINTS = np.array([
    [0.0, 0.93, 0.0], [0.09, 0.85, 0.0], [-0.09, 0.85, 0.0], [0.0, 1.05, -0.01],
    [0.10, 0.48, 0.01], [-0.10, 0.48, 0.01], [0.0, 1.18, 0.01], [0.10, 0.08, -0.03],
    [-0.10, 0.08, -0.03], [0.0, 1.24, 0.02], [0.11, 0.03, 0.10], [-0.11, 0.03, 0.10],
    [0.0, 1.45, -0.01], [0.07, 1.38, 0.0], [-0.07, 1.38, 0.0], [0.0, 1.55, 0.02],
    [0.18, 1.40, -0.01], [-0.18, 1.40, -0.01], [0.45, 1.40, -0.02], [-0.45, 1.40, -0.02],
    [0.70, 1.40, -0.01], [-0.70, 1.40, -0.01], [0.78, 1.39, -0.01], [-0.78, 1.39, -0.01],
]) - np.array([0.0, 1.15, 0.0])
# Ry(+90 deg), written out here rather than imported: SMPL (x, y, z) -> canonical (z, y, -x).
C = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
OCTA = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
OCTA_FACES = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                       [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


def random_smpl_model(seed=0, n_shape=10):
    rng = np.random.default_rng(seed)
    v = (SMPL_JOINTS[:, None] + 0.035 * OCTA[None] + 0.005 * rng.standard_normal((24, 6, 3))).reshape(-1, 3)
    n = len(v)
    owner = np.repeat(np.arange(24), 6)
    weights = np.zeros((n, 24))
    share = rng.uniform(0.5, 0.9, n)  # own joint, the rest on the parent: a real blend
    weights[np.arange(n), owner] = share
    parent = np.array([PARENTS[j] if PARENTS[j] >= 0 else 0 for j in owner])
    weights[np.arange(n), parent] += 1.0 - share
    jreg = np.zeros((24, n))
    jreg[owner, np.arange(n)] = rng.uniform(0.5, 1.5, n)
    jreg /= jreg.sum(1, keepdims=True)
    kintree = np.stack([np.array(PARENTS, np.int64) % 4294967296, np.arange(24)]).astype(np.uint32)
    return {
        "v_template": v, "shapedirs": 0.01 * rng.standard_normal((n, 3, n_shape)),
        "posedirs": np.zeros((n, 3, 207)), "J_regressor": jreg, "weights": weights,
        "kintree_table": kintree,
        "f": (np.arange(24)[:, None, None] * 6 + OCTA_FACES[None]).reshape(-1, 3).astype(np.uint32),
    }


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    torch.set_num_threads(1)
    d = tmp_path_factory.mktemp("smpl")
    data = random_smpl_model()
    np.savez(d / "SMPL_NEUTRAL.npz", **data)
    with open(d / "SMPL_NEUTRAL.pkl", "wb") as fh:
        pickle.dump(data, fh)
    return d, data


def expected_rest(data, betas):
    """Shaped template and regressed joints in the canonical frame, computed here by hand."""
    b = np.zeros(data["shapedirs"].shape[2])
    b[:len(betas)] = betas
    v = data["v_template"] + data["shapedirs"] @ b
    joints = data["J_regressor"] @ v
    v, joints = v @ C.T, joints @ C.T
    shift = np.array([-joints[0, 0], -v[:, 1].min(), -joints[0, 2]])
    return v + shift, joints + shift, shift


def smplx_reference(path):
    """smplx's own SMPL module, reading the .pkl itself. Its extra-keypoint selector indexes
    SMPL-mesh vertex ids, so it gets ids valid for this small mesh."""
    ids = {k: 0 for k in smplx.vertex_ids.vertex_ids["smplh"]}
    return smplx.create(str(path), model_type="smpl", vertex_ids=ids, num_betas=10, dtype=torch.float64)


BETAS = [1.5, -0.8, 0.3, 0.0, 2.0]


def test_rest_mesh_and_joints_follow_the_regressor(model):
    from splatting.rider.smpl_body import load_smpl_rider
    d, data = model
    for path in (d / "SMPL_NEUTRAL.npz", d / "SMPL_NEUTRAL.pkl", d):
        rider = load_smpl_rider(path, betas=BETAS, rider_id="me")
        v, joints, _ = expected_rest(data, BETAS)
        assert rider.id == "me" and rider.spec["body"] == "smpl"
        assert np.abs(rider.vertices.numpy() - v).max() < 1e-5
        assert np.abs(rider.joints.numpy() - joints).max() < 1e-5
        assert torch.allclose(rider.weights.double(), torch.from_numpy(data["weights"]), atol=1e-6)
        assert torch.equal(rider.faces, torch.from_numpy(data["f"].astype(np.int64)))
        assert rider.height_m == pytest.approx(v[:, 1].max() - v[:, 1].min(), abs=1e-5)
    # betas change the body
    plain = load_smpl_rider(d / "SMPL_NEUTRAL.npz")
    assert (plain.vertices - rider.vertices).abs().max() > 0.01


def test_canonical_frame(model):
    from splatting.rider.smpl_body import load_smpl_rider
    rider = load_smpl_rider(model[0] / "SMPL_NEUTRAL.npz", betas=BETAS)
    j, v = rider.joints, rider.vertices
    assert float(v[:, 1].min()) == pytest.approx(0.0, abs=1e-6)  # soles on Y = 0
    assert j[0, 0].abs() < 1e-6 and j[0, 2].abs() < 1e-6  # pelvis above the origin
    for name in ("hip", "shoulder", "elbow", "wrist", "ankle", "foot"):
        assert j[J[f"left_{name}"], 2] < -0.05 and j[J[f"right_{name}"], 2] > 0.05, name
    # facing +X: toes ahead of the ankles; T-pose: head above pelvis, arms out sideways
    assert (j[J["left_foot"], 0] - j[J["left_ankle"], 0]) > 0.08
    assert j[J["head"], 1] > j[J["pelvis"], 1] + 0.5
    assert abs(j[J["left_wrist"], 1] - j[J["left_shoulder"], 1]) < 0.02


def test_pose_vertices_agrees_with_smplx_forward(model):
    from splatting.rider.body import pose_vertices, posed_joints
    from splatting.rider.smpl_body import load_smpl_rider
    d, data = model
    rider = load_smpl_rider(d / "SMPL_NEUTRAL.npz", betas=BETAS)
    ref = smplx_reference(d / "SMPL_NEUTRAL.pkl")
    g = torch.Generator().manual_seed(1)
    aa = 0.6 * torch.randn(3, 24, 3, generator=g, dtype=torch.float64)
    betas = torch.zeros(3, 10, dtype=torch.float64)
    betas[:, :len(BETAS)] = torch.tensor(BETAS, dtype=torch.float64)
    with torch.no_grad():
        out = ref(betas=betas, global_orient=aa[:, 0], body_pose=aa[:, 1:].reshape(3, 69),
                  transl=torch.zeros(3, 3, dtype=torch.float64))
    _, _, shift = expected_rest(data, BETAS)
    want_v = out.vertices.numpy() @ C.T + shift
    want_j = out.joints[:, :24].numpy() @ C.T + shift
    Ct = torch.from_numpy(C)
    R = axis_angle_to_rotmat(aa)
    got_v = pose_vertices(rider, Ct @ R @ Ct.T).numpy()
    got_j = posed_joints(rider, Ct @ R @ Ct.T).numpy()
    assert np.abs(got_v - want_v).max() < 1e-5
    assert np.abs(got_j - want_j).max() < 1e-5
    # the frame conversion matters: SMPL-frame rotations used as they are land far off
    assert np.abs(pose_vertices(rider, R).numpy() - want_v).max() > 0.1


def test_works_with_ik_and_avatar(model):
    from splatting.gaussians.container import Gaussians
    from splatting.rider import ik
    from splatting.rider.avatar import RiderAvatar
    from splatting.rider.body import pose_vertices
    from splatting.rider.kinematics import forward_kinematics
    from splatting.rider.smpl_body import load_smpl_rider
    rider = load_smpl_rider(model[0] / "SMPL_NEUTRAL.npz", betas=BETAS)
    # IK: targets from a known pose of this rider are reached
    g = torch.Generator().manual_seed(2)
    aa = torch.as_tensor(ik.cycling_init_pose(rider.joints), dtype=torch.float64)[None].clone()
    for name in ik.IK_JOINTS:
        aa[:, J[name]] += 0.15 * torch.randn(1, 3, generator=g, dtype=torch.float64)
    joints, _ = forward_kinematics(rider.joints.double(), rodrigues(aa), torch.tensor([[0.1, -0.3, 0.0]]).double())
    lift = torch.tensor([0.0, ik.PELVIS_ABOVE_SEAT_M, 0.0], dtype=torch.float64)
    targets = {t: joints[:, J[j]] - (lift if t == "seat" else 0.0) for j, t in ik.DEFAULT_PAIRS}
    res = ik.solve(rider.joints, targets)
    for j, t in ik.DEFAULT_PAIRS:
        want = targets[t] + (lift if t == "seat" else 0.0)
        assert float((res.joints[0, J[j]].double() - want).norm()) < 0.01, (j, t)
    # avatar: Gaussians on mesh vertices follow the mesh's own LBS
    idx = torch.arange(0, len(rider.vertices), 7)
    n = len(idx)
    gs = Gaussians(rider.vertices[idx].clone(), torch.tensor([1.0, 0, 0, 0]).repeat(n, 1),
                   torch.full((n, 3), -5.0), torch.zeros(n), torch.rand(n, 1, 3))
    avatar = RiderAvatar.from_rider(gs, rider)
    R = rodrigues(aa).float()
    means = avatar.pose_tensors(R)["means"][0]
    assert (means - pose_vertices(rider, R)[0, idx]).abs().max() < 1e-4


def test_colours(model):
    from splatting.rider.smpl_body import DEFAULT_COLORS, load_smpl_rider
    colors = dict(DEFAULT_COLORS, top="#ff0000", shoes="#00ff00")
    rider = load_smpl_rider(model[0] / "SMPL_NEUTRAL.npz", colors=colors)
    dom = rider.weights.argmax(1)
    assert rider.colors.shape == rider.vertices.shape
    assert torch.allclose(rider.colors[dom == J["spine2"]], torch.tensor([1.0, 0.0, 0.0]))
    assert torch.allclose(rider.colors[dom == J["left_foot"]], torch.tensor([0.0, 1.0, 0.0]))
    with pytest.raises(UserError):
        load_smpl_rider(model[0] / "SMPL_NEUTRAL.npz", colors={"top": "red"})


def test_bad_model_files_are_user_errors(model, tmp_path):
    from splatting.rider.smpl_body import load_smpl_rider
    d, data = model
    with pytest.raises(UserError, match="not found"):
        load_smpl_rider(tmp_path / "SMPL_NEUTRAL.pkl")
    with pytest.raises(UserError, match="no SMPL_FEMALE"):
        load_smpl_rider(d, gender="female")
    with pytest.raises(UserError, match="gender"):
        load_smpl_rider(d, gender="robot")
    for name in ("junk.pkl", "junk.npz"):
        (tmp_path / name).write_bytes(b"\x00not a model at all" * 10)
        with pytest.raises(UserError, match="cannot read"):
            load_smpl_rider(tmp_path / name)
    # a pickle of classes from a package we lack (SMPL 1.0 files: chumpy) names the package
    (tmp_path / "chumpy.pkl").write_bytes(b"cno_such_pkg_for_smpl_test\nCh\n.")
    with pytest.raises(UserError, match="needs the 'no_such_pkg_for_smpl_test' package"):
        load_smpl_rider(tmp_path / "chumpy.pkl")
    np.savez(tmp_path / "partial.npz", v_template=data["v_template"])
    with pytest.raises(UserError, match="missing"):
        load_smpl_rider(tmp_path / "partial.npz")
    smplh = dict(data, weights=np.zeros((len(data["v_template"]), 52)))
    np.savez(tmp_path / "smplh.npz", **smplh)
    with pytest.raises(UserError, match="weights"):
        load_smpl_rider(tmp_path / "smplh.npz")
    with pytest.raises(UserError, match="betas"):
        load_smpl_rider(d / "SMPL_NEUTRAL.npz", betas=np.zeros(11))
    with pytest.raises(UserError, match="NaN"):
        load_smpl_rider(d / "SMPL_NEUTRAL.npz", betas=[np.nan])
    # a female model in the folder is found by gender
    np.savez(tmp_path / "SMPL_FEMALE.npz", **data)
    assert load_smpl_rider(tmp_path, gender="female").id == "smpl_female"


def test_roster_entry_dispatches_to_smpl(model, tmp_path, monkeypatch):
    from splatting.rider import roster
    from splatting.rider.roster import load_rider
    spec = {"id": "my_smpl", "body": "smpl", "model_path": str(model[0] / "SMPL_NEUTRAL.npz"),
            "betas": BETAS, "height_m": 1.7}
    missing = dict(spec, id="gone", model_path="data/no_such_dir/SMPL_NEUTRAL.pkl")
    specs = {s["id"]: s for s in (spec, missing)}
    monkeypatch.setattr(roster, "get_spec", lambda rid: specs[rid])
    load_rider.cache_clear()
    try:
        rider = load_rider("my_smpl")
        v, _, _ = expected_rest(model[1], BETAS)
        assert rider.id == "my_smpl" and np.abs(rider.vertices.numpy() - v).max() < 1e-5
        assert rider.spec["height_m"] == 1.7 and rider.spec["body"] == "smpl"
        with pytest.raises(UserError, match="not found"):
            load_rider("gone")
    finally:
        load_rider.cache_clear()


def test_roster_accepts_smpl_entries_and_lists_them(tmp_path):
    import yaml as _yaml

    from cyclist_formats.errors import UserError
    from splatting.rider.roster import describe, load_roster

    p = tmp_path / "riders.yaml"
    p.write_text(_yaml.safe_dump({"riders": [{"id": "my_smpl", "body": "smpl", "model_path": "models/SMPL_NEUTRAL.npz"}]}))
    (r,) = load_roster(p)
    assert describe(r).startswith("my_smpl") and "SMPL" in describe(r)
    p.write_text(_yaml.safe_dump({"riders": [{"id": "bad", "body": "smpl"}]}))
    with pytest.raises(UserError, match="model_path"):
        load_roster(p)

"""Rider body model (anny -> T-posed, canonical, 24 SMPL joints), roster and `rider` CLI.

The anny model data is built once into data/anny_cache/ (~80-100 s the first time on 2 cores,
a few seconds to load afterwards); every test here shares it through load_rider's cache."""
import numpy as np
import pytest
import torch

from cyclist_formats.errors import UserError
from splatting.rider.kinematics import JOINT_INDEX, JOINT_NAMES
from splatting.rider.roster import load_roster

J = JOINT_INDEX


@pytest.fixture(scope="session")
def riders():
    torch.set_num_threads(1)
    from splatting.rider.roster import load_rider
    return {r["id"]: load_rider(r["id"]) for r in load_roster()}


@pytest.fixture(scope="session")
def rider(riders):
    return riders["f_adult_athletic_170"]


def test_roster_spans_people():
    roster = load_roster()
    assert len(roster) >= 12
    heights = [r["height_m"] for r in roster]
    assert min(heights) <= 1.50 and max(heights) >= 1.95
    assert {r["sex"] for r in roster} == {"female", "male"}
    assert len({r["build"] for r in roster}) >= 3
    assert len({r["age_years"] // 20 for r in roster}) >= 3  # teens, adults, seniors


def test_roster_rejects_bad_file(tmp_path):
    p = tmp_path / "r.yaml"
    p.write_text("riders:\n- id: a\n  height_m: 1.7\n  phenotype: {gender: 2}\n")
    with pytest.raises(UserError, match="phenotype.gender"):
        load_roster(p)
    p.write_text("riders: [\n")
    with pytest.raises(UserError, match="bad YAML"):
        load_roster(p)


def test_heights_match_roster(riders):
    for r in load_roster():
        body = riders[r["id"]]
        v = body.vertices[:body.body_vertex_count].numpy()  # the body, without helmet or hair
        assert abs(v[:, 1].max() - v[:, 1].min() - r["height_m"]) < 0.02, r["id"]
        assert abs(v[:, 1].min()) < 1e-6  # soles on the ground


def test_canonical_frame(rider):
    j = rider.joints.numpy()
    assert abs(j[0, 0]) < 1e-6 and abs(j[0, 2]) < 1e-6  # pelvis on the Y axis
    assert j[J["head"], 1] > j[J["neck"], 1] > j[J["pelvis"], 1] > j[J["left_knee"], 1]
    # Facing +X: toes ahead of the ankles; left side at -Z.
    assert j[J["left_foot"], 0] > j[J["left_ankle"], 0] + 0.05
    for name in JOINT_NAMES:
        if name.startswith("left_"):
            assert j[J[name], 2] < -0.01, name
    # T-pose: arms horizontal and straight out.
    for s in ("left", "right"):
        arm = j[J[f"{s}_hand"]] - j[J[f"{s}_shoulder"]]
        assert abs(arm[1]) < 0.03 * np.linalg.norm(arm) + 0.01


def test_mirror_symmetry(riders):
    for body in riders.values():
        j = body.joints.numpy()
        for name in JOINT_NAMES:
            if name.startswith("left_"):
                l, r = j[J[name]], j[J["right_" + name[5:]]]
                np.testing.assert_allclose(l * [1, 1, -1], r, atol=2e-3, err_msg=name)


def _winding_numbers(points, verts, faces):
    """Generalised winding number of each point w.r.t. a triangle mesh (~1 inside, ~0 outside)."""
    a, b, c = (verts[faces[:, k]][None] - points[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    det = np.einsum("pfi,pfi->pf", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("pfi,pfi->pf", a, b) * lc
           + np.einsum("pfi,pfi->pf", b, c) * la + np.einsum("pfi,pfi->pf", c, a) * lb)
    return np.arctan2(det, den).sum(1) / (2 * np.pi)


def test_joints_inside_body(riders):
    for rid in ("f_teen_slim_150", "m_adult_heavy_176", "m_senior_athletic_195"):
        body = riders[rid]
        w = _winding_numbers(body.joints.double().numpy(), body.vertices.double().numpy(),
                             body.faces.numpy())
        # The mesh's outward orientation may be either sign; inside means |w| ~ 1.
        bad = [n for n, x in zip(JOINT_NAMES, np.abs(w)) if x < 0.5]
        assert not bad, (rid, bad)
        outside = np.abs(_winding_numbers(np.array([[0.0, 1.0, 0.5], [0.5, 1.0, 0.0]]),
                                          body.vertices.double().numpy(), body.faces.numpy()))
        assert (outside < 0.1).all()


def test_weights(rider):
    w = rider.weights.numpy()
    assert w.shape == (rider.vertices.shape[0], 24)
    assert (w >= 0).all()
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-5)
    # Every joint except the leaf knuckles/toes drives some vertex.
    assert (w.max(0) > 0.5).sum() >= 20


def test_lbs_identity_and_rigid(rider):
    from splatting.rider.body import pose_vertices
    from splatting.rotations import axis_angle_to_rotmat
    eye = torch.eye(3, dtype=torch.float64).repeat(2, 24, 1, 1)
    v = pose_vertices(rider, eye, torch.zeros(2, 3, dtype=torch.float64))
    np.testing.assert_allclose(v[1].numpy(), rider.vertices.double().numpy(), atol=1e-6)
    # A root rotation + translation moves the whole mesh rigidly about the pelvis.
    rots = eye.clone()
    R = axis_angle_to_rotmat(torch.tensor([0.3, -0.5, 0.2], dtype=torch.float64))
    rots[0, 0] = R
    t = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    v = pose_vertices(rider, rots, t.expand(2, 3))[0]
    p0 = rider.joints[0].double()
    expect = (rider.vertices.double() - p0) @ R.T + p0 + t
    np.testing.assert_allclose(v.numpy(), expect.numpy(), atol=1e-5)


def test_lbs_knee_moves_only_shin(rider):
    from splatting.rider.body import pose_vertices
    rots = torch.eye(3, dtype=torch.float64).repeat(1, 24, 1, 1)
    a = 1.2  # rotate the left knee about +Z: the shin swings
    rots[0, J["left_knee"]] = torch.tensor([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0],
                                            [0, 0, 1]], dtype=torch.float64)
    v = pose_vertices(rider, rots)[0].numpy()
    moved = np.linalg.norm(v - rider.vertices.numpy(), axis=1) > 1e-4
    y = rider.vertices.numpy()[:, 1]
    knee_y = rider.joints[J["left_knee"], 1].item()
    assert moved.sum() > 200
    assert (y[moved] < knee_y + 0.15).all()  # nothing above the thigh moves
    assert not moved[rider.vertices.numpy()[:, 2] > 0.05].any()  # the right side stays


def test_export_ply_has_colours(rider, tmp_path):
    from plyfile import PlyData
    from splatting.rider.body import export_rider
    out = tmp_path / "r.ply"
    export_rider(rider, out)
    ply = PlyData.read(str(out))
    v = ply["vertex"]
    assert v.count == rider.vertices.shape[0]
    cols = np.stack([v["red"], v["green"], v["blue"]], 1)
    top = np.array([int(rider.spec["colors"]["top"][i:i + 2], 16) for i in (1, 3, 5)])
    assert (np.abs(cols - top).sum(1) == 0).sum() > 500  # a jersey exists
    assert len(np.unique(cols, axis=0)) >= 4


def test_cli_list_and_errors(capsys, tmp_path):
    from splatting.cli import main
    assert main(["rider", "--list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    from splatting.rider.roster import all_riders  # the file's riders, then any imported ones
    assert [l.split()[0] for l in lines] == [r["id"] for r in all_riders()]
    assert main(["rider", "--id", "nobody", "--out", str(tmp_path / "x.ply")]) == 2
    assert "unknown rider id" in capsys.readouterr().err
    assert not (tmp_path / "x.ply").exists()


def test_cli_export_posed(riders, tmp_path):
    import trimesh
    from splatting.cli import main
    out = tmp_path / "p.obj"
    assert main(["rider", "--id", "m_adult_slim_190", "--out", str(out), "--theta-p-deg", "90"]) == 0
    m = trimesh.load(out, process=False)
    assert len(m.vertices) == riders["m_adult_slim_190"].vertices.shape[0]
    assert m.vertices[:, 1].max() < 1.5  # seated, pelvis at the origin: head well below 1.9 m

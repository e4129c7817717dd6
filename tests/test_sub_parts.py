"""Wheel and pedal sub-parts (docs/contract.md "Sub-parts"): the procedural generator cuts them out
of the same geometry, Blender spins the wheels and keeps the pedals level, the Gaussian model does
the same at every wheel / crank angle (checked against Blender's posed mesh), a bike without
sub-parts works as before, and a riding cyclist's wheels roll without slip."""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from addon.core.procedural import build, layout
from addon.core.procedural import spec as specs
from cyclist_formats import bike_folder, instances

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MAKE = os.path.join(ROOT, "blender_scripts", "make_bikes.py")


def _bicycle(style="road"):
    return next(s for s in specs.library_specs(8, 0, extras=False) if s["style"] == style)


# ---------------------------------------------------------------- numpy: the split itself

@pytest.mark.parametrize("style", ["road", "city"])
def test_sub_parts_are_cut_from_the_same_geometry(style):
    s = _bicycle(style)
    _, whole = build.part_builders(s)
    L, split = build.part_builders(s, sub_parts=True)
    assert list(split) == ["frame", "steering", "crank", "front_wheel", "rear_wheel", "pedal_left", "pedal_right"]
    # every triangle lands in exactly one piece: the same surface, sorted differently
    tris = lambda mbs: sorted(tuple(np.round(mb.vertices[list(f)], 6).ravel())  # noqa: E731
                              for mb in mbs for f in mb.faces)
    assert tris(whole.values()) == tris(split.values())
    kp = layout.keypoints(s, L)
    for wheel, axle, main in (("front_wheel", "front_axle", "steering"), ("rear_wheel", "rear_axle", "frame")):
        V = split[wheel].vertices
        r = np.hypot(*(V[:, :2] - np.array(kp[axle])[:2]).T)
        assert abs(r.max() - L["R"]) < 1e-6  # the tyre's outer radius: the whole wheel is there
        # nothing of the wheel is left on its main part: no vertex of the main part on the tyre
        rm = np.hypot(*(split[main].vertices[:, :2] - np.array(kp[axle])[:2]).T)
        zm = np.abs(split[main].vertices[:, 2])
        assert not ((np.abs(rm - L["R"]) < 1e-4) & (zm < 1e-4)).any()
    for side in ("pedal_left", "pedal_right"):
        c = split[side].vertices.mean(0)
        assert np.linalg.norm(c - np.array(kp[side])) < 0.01  # the pedal body around its keypoint


def test_gear_ratio_is_chainring_over_cog():
    s = _bicycle("city")
    g = build.gear_ratio(s)
    assert 1.0 < g < 5.0
    cogs = build.tubes.cog_radii(s)
    teeth = round(2 * math.pi * cogs[len(cogs) // 2] / 0.0127)  # 1/2-inch chain pitch
    assert g == pytest.approx(s["chainring_teeth"] / teeth, abs=1e-5)
    scooter = next(x for x in specs.library_specs(1, 0) if x["rideable"] == "kick_scooter")
    assert build.gear_ratio(scooter) is None
    assert list(build.part_builders(scooter, sub_parts=True)[1]) == ["frame", "steering"]


def test_meta_sub_parts_are_checked():
    assert bike_folder.sub_parts({}) == []
    assert bike_folder.sub_parts({"sub_parts": ["pedal_left", "rear_wheel"], "gear_ratio": 2.5}) == ["rear_wheel", "pedal_left"]
    for bad in ({"sub_parts": ["spokes"]}, {"sub_parts": ["front_wheel"]}, {"sub_parts": ["front_wheel"], "gear_ratio": -1},
                {"sub_parts": "front_wheel"}):
        with pytest.raises(bike_folder.UserError):
            bike_folder.sub_parts(bad)
    assert set(instances.SUB_PART_IDS) == set(bike_folder.SUB_PARTS)
    assert all(instances.SUB_PART_IDS[k] == instances.PART_IDS[v] for k, v in bike_folder.SUB_PART_OF.items())


# ---------------------------------------------------------------- Blender vs the Gaussian model

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def bikes(tmp_path_factory):
    pytest.importorskip("bpy")
    out = {}
    for flag in ("sub", "plain"):
        d = tmp_path_factory.mktemp(flag)
        r = subprocess.run([sys.executable, MAKE, "--out", str(d), "--count", "1", "--seed", "5", "--no-extras"]
                           + (["--no-sub-parts"] if flag == "plain" else []), capture_output=True, text=True)
        assert r.returncode == 0, r.stderr[-2000:]
        out[flag] = d / "bikes" / os.listdir(d / "bikes")[0]
    return out


def _rest_vertices(bike_dir):
    """{part: canonical rest vertices} of every part mesh, read from bike.blend."""
    from addon.core import frames
    from addon.core.bike_asset import open_bike

    bike = open_bike(str(bike_dir))
    out = {}
    for name, o in bike["parts"].items():
        V = np.empty(len(o.data.vertices) * 3)
        o.data.vertices.foreach_get("co", V)
        mw = np.array(o.matrix_world)
        out[name] = frames.to_canonical(V.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3])
    return out, {n: o.pass_index for n, o in bike["parts"].items()}


def _blender_posed_vertices(bike_dir, pose, wheel_deg=None):
    from addon.core import frames
    from addon.core.rig.articulation import apply_pose, posed_keypoints
    from addon.core.bike_asset import open_bike

    bike = open_bike(str(bike_dir))
    apply_pose(bike["armature"], pose[0], pose[1], pose[2:5], pose[5:8], wheel_deg=wheel_deg)
    out, rot = {}, {}
    for name, o in bike["parts"].items():
        V = np.empty(len(o.data.vertices) * 3)
        o.data.vertices.foreach_get("co", V)
        mw = np.array(o.matrix_world)
        out[name] = frames.to_canonical(V.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3])
        rot[name] = frames.matrix_to_canonical(mw)[:3, :3]
    return out, rot, posed_keypoints(bike["armature"])


def _model_from_vertices(bike_dir, verts):
    """A BikeModel whose Gaussians sit on the rest mesh vertices: posing it moves them as the
    model moves its parts."""
    from splatting.bike.model import BikeModel
    from splatting.gaussians.container import Gaussians

    parts = {}
    for name, V in verts.items():
        n = len(V)
        parts[name] = Gaussians(means=torch.tensor(V, dtype=torch.float64), quats=torch.tensor([[1.0, 0, 0, 0]], dtype=torch.float64).repeat(n, 1),
                                log_scales=torch.full((n, 3), -5.0, dtype=torch.float64),
                                opacity_logits=torch.zeros(n, dtype=torch.float64), sh=torch.zeros(n, 1, 3, dtype=torch.float64))
    kp_doc = json.loads((bike_dir / "keypoints.json").read_text())
    meta = json.loads((bike_dir / "meta.json").read_text())
    return BikeModel(parts, kp_doc, meta)


def test_generated_bike_has_sub_parts_with_their_main_ids(bikes):
    meta = json.loads((bikes["sub"] / "meta.json").read_text())
    assert meta["sub_parts"] == list(bike_folder.SUB_PARTS) and 1.0 < meta["gear_ratio"] < 5.0
    _, ids = _rest_vertices(bikes["sub"])
    assert ids == {**instances.PART_IDS, **instances.SUB_PART_IDS}
    plain = json.loads((bikes["plain"] / "meta.json").read_text())
    assert plain["sub_parts"] == []
    _, ids = _rest_vertices(bikes["plain"])
    assert ids == instances.PART_IDS


@pytest.mark.parametrize("pose,wheel", [
    ([0, 0, 0, 0, 0, 0, 0, 0], None),
    ([37, 0, 0, 0, 0, 0, 0, 0], None),
    ([90, 25, 8, 140, -5, 0.4, 0.0, -0.7], None),
    ([215, -30, -12, 300, 3, -1.0, 0.1, 0.5], None),
    ([215, -30, -12, 300, 3, -1.0, 0.1, 0.5], 1234.5),  # a coasting wheel: its own angle
    ([0, 10, 0, 0, 0, 0, 0, 0], -75.0),
])
def test_posed_sub_parts_match_blender(bikes, pose, wheel):
    """Every vertex of every part (sub-parts included) posed by the model lands where Blender's
    armature puts it (<= 1 mm), at several crank and wheel angles; the keypoints agree too."""
    rest, _ = _rest_vertices(bikes["sub"])
    model = _model_from_vertices(bikes["sub"], rest)
    assert model.part_names == ["frame", "steering", "crank", "front_wheel", "rear_wheel", "pedal_left", "pedal_right"]
    blender, _, kp_b = _blender_posed_vertices(bikes["sub"], pose, wheel)
    posed = model.pose(torch.tensor(pose, dtype=torch.float64), wheel_deg=wheel)
    means = posed.gaussians.means.numpy()
    for name, (a, e) in zip(model.part_names, model.ranges):
        err = np.abs(means[a:e] - blender[name]).max()
        assert err <= 1e-3, f"{name} off Blender's posed mesh by {err * 1000:.2f} mm at {pose}, wheel {wheel}"
    for k, xyz in kp_b.items():
        assert np.linalg.norm(posed.keypoints[k].numpy() - xyz) <= 1e-3, k


def test_wheels_spin_and_pedals_stay_level_in_blender(bikes):
    """Geometry, not conventions: the tyre's top moves forward as theta_p grows (forward rolling),
    by gear_ratio x theta_p, and the pedal bodies keep the frame's orientation all round."""
    meta = json.loads((bikes["sub"] / "meta.json").read_text())
    kp = json.loads((bikes["sub"] / "keypoints.json").read_text())["keypoints"]
    rest, _ = _rest_vertices(bikes["sub"])
    for theta_p in (0.0, 45.0, 90.0, 180.0, 270.0):
        posed, rot, _ = _blender_posed_vertices(bikes["sub"], [theta_p, 0, 0, 0, 0, 0, 0, 0])
        for side in ("pedal_left", "pedal_right"):
            assert np.allclose(rot[side], np.eye(3), atol=1e-6), f"{side} tilted at theta_p {theta_p}"
        # the rear wheel turned by -theta_p * gear about +Z through its axle
        a = np.radians(-theta_p * meta["gear_ratio"])
        c, s = math.cos(a), math.sin(a)
        ax = np.array(kp["rear_axle"])
        want = (rest["rear_wheel"] - ax) @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) + ax
        assert np.abs(posed["rear_wheel"] - want).max() < 1e-4
    # a small forward pedal stroke moves the top of the wheel forward (+X)
    top = np.argmax(rest["front_wheel"][:, 1])
    posed, _, _ = _blender_posed_vertices(bikes["sub"], [5.0, 0, 0, 0, 0, 0, 0, 0])
    assert posed["front_wheel"][top, 0] > rest["front_wheel"][top, 0] + 0.01


def test_bike_without_sub_parts_works_as_before(bikes):
    rest, _ = _rest_vertices(bikes["plain"])
    assert set(rest) == {"frame", "steering", "crank"}
    model = _model_from_vertices(bikes["plain"], rest)
    assert model.part_names == ["frame", "steering", "crank"] and model.gear_ratio is None
    pose = [120, 20, 5, 33, 0, 0.2, 0, 0.3]
    blender, _, kp_b = _blender_posed_vertices(bikes["plain"], pose)
    means = model.pose(torch.tensor(pose, dtype=torch.float64)).gaussians.means.numpy()
    for name, (a, e) in zip(model.part_names, model.ranges):
        assert np.abs(means[a:e] - blender[name]).max() <= 1e-3, name
    # the same spec's triangles, the wheels inside frame / steering, the pedals inside the crank
    m_sub = json.loads((bikes["sub"] / "meta.json").read_text())["triangles"]
    m_plain = json.loads((bikes["plain"] / "meta.json").read_text())["triangles"]
    assert sum(m_sub.values()) == sum(m_plain.values())
    assert m_plain["frame"] == m_sub["frame"] + m_sub["rear_wheel"]


# ---------------------------------------------------------------- rolling without slip

def test_sequence_wheels_roll_without_slip(bikes):
    """A cyclist braking to a stop (coasting: the crank stands still) along a trajectory: the
    wheel Gaussians turn by distance / radius, so the tyre's contact point stands still on the
    road while the bike moves at up to several m/s; with the crank-coupled default they would slide."""
    from splatting.dataset.sequences import trajectory as tj

    rest, _ = _rest_vertices(bikes["sub"])
    model = _model_from_vertices(bikes["sub"], rest)
    kp = bike_folder.read_keypoints(bikes["sub"])
    geom = tj.bike_geometry(kp)
    fps = 10
    tr = tj.integrate(30, fps, {"kind": "stop", "v": 6.0, "t0": 0.5, "ramp": 2.0}, [], geom, (0.0, 0.0), 30.0, 2.5, 0.0)
    P = torch.tensor(tj.poses(tr), dtype=torch.float64)
    W = torch.tensor(tr["wheel_deg"], dtype=torch.float64)
    assert np.allclose(np.radians(tr["wheel_deg"]) * geom["r"], tr["s"])  # angle = distance / radius
    # finite differences of the posed wheel points over a short step of the fine grid
    dt = 1.0 / (fps * tj.SUBSTEPS)
    fine = torch.tensor(tr["fine_pose"], dtype=torch.float64)
    fw = torch.tensor(tr["fine_wheel_deg"], dtype=torch.float64)
    checked = 0
    for i in range(0, len(fine) - 1, 37):
        v = float(np.hypot(*(fine[i + 1, [5, 7]] - fine[i, [5, 7]]).numpy()) / dt)
        if v < 0.5:
            continue
        for wheel in ("front_wheel", "rear_wheel"):
            a, e = model.ranges[model.part_names.index(wheel)]
            m0 = model.pose(fine[i], wheel_deg=fw[i]).gaussians.means[a:e].numpy()
            m1 = model.pose(fine[i + 1], wheel_deg=fw[i + 1]).gaussians.means[a:e].numpy()
            low = np.argmin(m0[:, 1])  # the contact point: the lowest point of the tyre
            assert m0[low, 1] < 0.002
            slip = np.linalg.norm(m1[low] - m0[low]) / dt
            # the nearest tyre vertex sits up to half a tyre segment (2.5 deg) off the bottom: its
            # speed there is v * sin(2.5 deg) ~ 0.04 v, a sliding tyre's would be v
            assert slip < 0.1 * v, f"{wheel} contact point slides at {slip:.2f} m/s (bike {v:.2f} m/s)"
            # the crank-coupled default (theta_p x gear) does slide while coasting
            if not tr["pedalling"][min(i // tj.SUBSTEPS, len(tr["pedalling"]) - 1)]:
                d0 = model.pose(fine[i]).gaussians.means[a:e].numpy()
                d1 = model.pose(fine[i + 1]).gaussians.means[a:e].numpy()
                assert np.linalg.norm(d1[low] - d0[low]) / dt > 0.5 * v
            checked += 1
    assert checked >= 4
    # and the frames' own angles make the same wheel turn by exactly distance / radius
    H = model.part_transforms(P, wheel_deg=W)["rear_wheel"].numpy()
    Hf = model.part_transforms(P, wheel_deg=W)["frame"].numpy()
    for f in (0, 10, 29):
        R_rel = Hf[f, :3, :3].T @ H[f, :3, :3]  # the wheel's spin in the frame's axes
        spin = math.atan2(R_rel[1, 0], R_rel[0, 0])
        want = -math.radians(tr["wheel_deg"][f])
        assert abs((spin - want + math.pi) % (2 * math.pi) - math.pi) < 1e-6


# ---------------------------------------------------------------- sub-parts for curated bikes

def test_add_sub_parts_finds_the_generators_pieces(bikes, tmp_path):
    """add_sub_parts.py (what curate.py runs after saving) on the bike made without sub-parts cuts
    exactly the pieces the generator tags: the same triangles per part as the bike made with
    them; the rebuilt rig poses them as the model does; a second run is refused."""
    import shutil

    d = tmp_path / "bike"
    shutil.copytree(bikes["plain"], d)
    script = os.path.join(ROOT, "blender_scripts", "add_sub_parts.py")
    r = subprocess.run([sys.executable, script, "--bike", str(d)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
    meta = json.loads((d / "meta.json").read_text())
    want = json.loads((bikes["sub"] / "meta.json").read_text())
    assert meta["sub_parts"] == list(bike_folder.SUB_PARTS)
    assert meta["triangles"] == want["triangles"]
    assert meta["gear_ratio"] == want["gear_ratio"]  # meta.json's own (a curated bike's default: 2.6)
    rest, ids = _rest_vertices(d)
    assert ids == {**instances.PART_IDS, **instances.SUB_PART_IDS}
    model = _model_from_vertices(d, rest)
    pose = [75, -20, 6, 210, 0, 0.3, 0, -0.4]
    blender, rot, _ = _blender_posed_vertices(d, pose)
    means = model.pose(torch.tensor(pose, dtype=torch.float64)).gaussians.means.numpy()
    for name, (a, e) in zip(model.part_names, model.ranges):
        assert np.abs(means[a:e] - blender[name]).max() <= 1e-3, name
    assert np.allclose(rot["pedal_left"], rot["frame"], atol=1e-6)  # level: the frame's orientation
    r = subprocess.run([sys.executable, script, "--bike", str(d)], capture_output=True, text=True)
    assert r.returncode != 0 and "already has sub-parts" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = subprocess.run([sys.executable, script, "--bike", str(tmp_path / "nope")], capture_output=True, text=True)
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1


def test_sub_part_finder_matches_the_generator_on_every_style():
    """curation.sub_parts on each style's unsplit part meshes labels exactly the faces the
    generator tags (area agreement 1.0): wheels with cassettes, disc rotors, suspension forks;
    platform and cage pedals."""
    from addon.core.curation import sub_parts as sp

    for s in specs.library_specs(8, 0, extras=False):
        L, parts = build.part_builders(s)
        kp = {k: np.array(v) for k, v in layout.keypoints(s, L).items()}
        found = set()
        for name, mb in parts.items():
            V = mb.vertices
            tris, tags = [], []
            for f, t in zip(mb.faces, mb._tags):
                for k in range(1, len(f) - 1):
                    tris.append((f[0], f[k], f[k + 1]))
                    tags.append(t)
            T, tags = np.array(tris), np.array(tags, dtype=object)
            for sub, sel in sp.sub_part_triangles(name, V, T, kp).items():
                assert np.array_equal(sel, tags == sub), f"{s['bike_id']} {sub}"
                found.add(sub)
        assert found == set(bike_folder.SUB_PARTS), s["bike_id"]

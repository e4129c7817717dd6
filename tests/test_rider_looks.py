"""Roster riders' looks (splatting/rider/looks.py): patterns, hems, hair, helmets, backpacks, skin tones,
drawn deterministically per rider and carried by the mesh through the IK's poses."""
import numpy as np
import pytest
import torch

from helpers import RIDER, street_config, write_test_bike

from cyclist_formats.errors import UserError
from splatting.rider import looks
from splatting.rider.body import REGIONS, build_rider, pose_vertices, posed_joints
from splatting.rider.kinematics import JOINT_INDEX
from splatting.rider.roster import get_spec, load_roster, load_rider

HELMETED = "f_adult_slim_160"  # drawn: helmet, long hair (a ponytail under it), stripes


def _with_look(rider_id, **fields):
    spec = dict(get_spec(rider_id))
    spec["look"] = {**(spec.get("look") or {}), **fields}
    return build_rider(spec)


def _lum(rgb):
    return np.asarray(rgb, float) @ [0.2126, 0.7152, 0.0722]


def test_looks_are_drawn_per_id_deterministically_and_vary_over_the_roster():
    roster = [r for r in load_roster() if r.get("body", "anny") == "anny"]
    drawn = [looks.look_of(r) for r in roster]
    assert drawn == [looks.look_of(r) for r in roster]  # a function of the entry
    assert looks.draw_look("a") != looks.draw_look("b")
    assert {d["helmet"] for d in drawn} == {True, False}
    assert sum(d["bag"] == "backpack" for d in drawn) >= 2
    assert len({d["hair"] for d in drawn}) >= 3
    assert len({d["top_pattern"] for d in drawn}) >= 4
    assert {d["sleeves"] for d in drawn} == {"short", "long"} and {d["legs"] for d in drawn} == {"shorts", "long"}
    # grey hair for the seniors
    for r, d in zip(roster, drawn):
        if r["age_years"] >= 55 and "hair_colour" not in (r.get("look") or {}):
            assert d["hair_colour"] in looks.GREY_HAIR


def test_skin_tones_differ_across_the_roster():
    skins = {r["colors"]["skin"] for r in load_roster() if "colors" in r}
    lum = sorted(_lum(looks.hex_rgb(s)) for s in skins)
    assert len(skins) >= 8
    assert lum[-1] - lum[0] > 0.5  # from very dark to very light
    assert sum(v < 0.4 for v in lum) >= 3 and sum(v > 0.6 for v in lum) >= 3


def test_roster_look_block_is_validated(tmp_path):
    base = ("riders:\n- id: a\n  height_m: 1.7\n  phenotype: {gender: 0, age: 0.8, muscle: 0.5, weight: 0.5, "
            "proportions: 0.5, height: 0.4}\n  colors: {skin: '#aa8866', top: '#ff0000', bottom: '#000000', "
            "shoes: '#ffffff', helmet: '#00ff00'}\n")
    p = tmp_path / "r.yaml"
    p.write_text(base + "  look: {helmet: true, hair: bun}\n")
    assert load_roster(p)[0]["look"] == {"helmet": True, "hair": "bun"}
    for bad, msg in (("{hair: mohawk}", "look.hair"), ("{helmet: 1}", "look.helmet"), ("{cape: red}", "unknown look field"),
                     ("{accent: red}", "look.accent"), ("[1, 2]", "look must be a mapping")):
        p.write_text(base + f"  look: {bad}\n")
        with pytest.raises(UserError, match=msg):
            load_roster(p)


@pytest.mark.parametrize("pattern", [p for p in looks.TOP_PATTERNS if p != "plain"])
def test_jersey_pattern_is_painted(pattern):
    r = _with_look(RIDER, top_pattern=pattern, accent="#ffff00", bag="none")
    plain = _with_look(RIDER, top_pattern="plain", accent="#ffff00", bag="none")
    top = (r.regions == REGIONS.index("top")).numpy()
    c, c0 = r.colors.numpy()[top], plain.colors.numpy()[top]
    accent = np.all(np.abs(c - looks.hex_rgb("#ffff00")) < 1e-6, axis=1)
    assert 0.005 < accent.mean() < 0.8, pattern  # a pattern, not a new plain colour
    assert not np.all(np.abs(c0 - looks.hex_rgb("#ffff00")) < 1e-6, axis=1).any()
    # the pattern is the only difference on the jersey (its hems darken whatever colour is under them)
    rim = looks.boundary(r.faces.numpy(), top)[top]
    assert np.allclose(c[~accent & ~rim], c0[~accent & ~rim])


def test_hems_are_darker_than_their_garment():
    r = _with_look(RIDER, top_pattern="plain", bag="none")
    top = (r.regions == REGIONS.index("top")).numpy()
    rim = looks.boundary(r.faces.numpy(), top)
    base = looks.hex_rgb(r.spec["colors"]["top"])
    assert rim.sum() > 50
    assert np.allclose(r.colors.numpy()[rim], base * 0.55, atol=1e-6)
    inner = top & ~rim
    assert np.allclose(np.median(r.colors.numpy()[inner], 0), base, atol=1e-6)


def test_helmet_hair_and_bag_regions_follow_the_look():
    bare = _with_look(RIDER, helmet=False, hair="bald", bag="none")
    full = _with_look(RIDER, helmet=True, hair="long", bag="backpack")
    counts = lambda r: torch.bincount(r.regions, minlength=len(REGIONS)).numpy()
    cb, cf = counts(bare), counts(full)
    for name in ("helmet", "hair", "bag"):
        assert cb[REGIONS.index(name)] == 0 and cf[REGIONS.index(name)] > 100, name
    # accessories come after the body, whose vertices are the same in both
    assert bare.body_vertex_count == full.body_vertex_count == len(bare.vertices)
    n = full.body_vertex_count
    assert len(full.vertices) > n + 1000
    assert torch.equal(full.vertices[:n], bare.vertices[:n]) and torch.equal(full.weights[:n], bare.weights[:n])
    assert torch.allclose(full.weights.sum(1), torch.ones(len(full.vertices)), atol=1e-5)
    # the body's height is the roster's, the helmet rises above it
    assert abs(full.height_m - full.spec["height_m"]) < 0.02
    assert float(full.vertices[:, 1].max()) > float(full.vertices[:n, 1].max()) + 0.01
    # hair shows: the scalp's hair volume and a ponytail hang lower at the back than the helmet's rim
    hair = (full.regions == REGIONS.index("hair")).numpy()
    helmet = (full.regions == REGIONS.index("helmet")).numpy()
    assert full.vertices[hair, 1].min() < full.vertices[helmet, 1].min()


def test_keypoint_regressor_ignores_accessories():
    from splatting.dataset.person_keypoints import regressor
    bare = _with_look(RIDER, helmet=False, hair="bald", bag="none")
    full = _with_look(RIDER, helmet=True, hair="bun", bag="backpack")
    a, b = regressor(bare), regressor(full)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert max(int(v.max()) for v in b.values()) < full.body_vertex_count


@pytest.fixture(scope="module")
def ik_poses(tmp_path_factory):
    """The cyclist's IK poses (local rotations, root) of the helmeted rider at four crank and steering angles."""
    torch.set_num_threads(1)
    root = str(tmp_path_factory.mktemp("looks_ik"))
    write_test_bike(root)
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets
    cfg = resolve_assets(validate(street_config(root, riders=[HELMETED])))
    assets = Assets(cfg)
    cyc = assets.cyclist("city_t", HELMETED)
    out = []
    for tp, ts, yaw in ((0.0, 0.0, 0.0), (90.0, 20.0, 45.0), (200.0, -25.0, 180.0), (300.0, 10.0, -90.0)):
        cyc.pose(torch.tensor([tp, ts, 0, yaw, 0, 0, 0, 6.0], dtype=torch.float64))
        out.append(assets.avatars[HELMETED].last)
    return out


def test_helmet_and_hair_stay_on_the_head_through_ik_poses(ik_poses):
    r = load_rider(HELMETED)
    look = looks.look_of(r.spec)
    assert look["helmet"] and look["hair"] != "bald"
    helmet = torch.nonzero(r.regions == REGIONS.index("helmet")).squeeze(1)
    hair = torch.nonzero((r.regions == REGIONS.index("hair")) & (torch.arange(len(r.vertices)) >= r.body_vertex_count)).squeeze(1)
    head = JOINT_INDEX["head"]
    skull = torch.nonzero((r.weights[:, head] > 0.999) & (torch.arange(len(r.vertices)) < r.body_vertex_count)).squeeze(1)
    assert len(helmet) > 100 and len(hair) > 50 and len(skull) > 100
    rest = r.vertices.double()

    def inside(pts, shell):  # inside the helmet: each point is nearer the shell's centroid than the shell along its ray
        c = shell.mean(0)
        d = pts - c
        s = shell - c
        cos = (d / d.norm(dim=1, keepdim=True)) @ (s / s.norm(dim=1, keepdim=True)).T
        nearest = cos.argmax(1)
        return d.norm(dim=1) < s.norm(dim=1)[nearest]

    top = skull[rest[skull, 1] > rest[helmet, 1].min() + 0.03]  # the skull well above the rim
    assert bool(inside(rest[top], rest[helmet]).all())
    turn = torch.tensor([[0.766, 0.0, 0.643], [0.0, 1.0, 0.0], [-0.643, 0.0, 0.766]], dtype=torch.float64)  # 40 deg
    looks_back = []  # the same poses with a shoulder check: the head turned 40 degrees on the neck
    for rot, root in ik_poses:
        rot2 = rot.double().clone()
        rot2[:, head] = turn @ rot2[:, head]
        looks_back.append((rot2, root))
    for rot, root in list(ik_poses) + looks_back:
        v = pose_vertices(r, rot.double(), root.double())[0]
        # rigid with the skull: every distance between helmet (or hair) and skull vertices is kept
        for part in (helmet, hair):
            d0 = torch.cdist(rest[part][::7], rest[skull][::5])
            d1 = torch.cdist(v[part][::7], v[skull][::5])
            assert float((d1 - d0).abs().max()) < 1e-4
        assert bool(inside(v[top], v[helmet]).all())


def test_backpack_rides_on_the_back_through_ik_poses(ik_poses):
    r = _with_look(HELMETED, bag="backpack")
    bag = torch.nonzero(r.regions == REGIONS.index("bag")).squeeze(1)
    J = JOINT_INDEX
    for rot, root in ik_poses:
        v = pose_vertices(r, rot.double(), root.double())[0]
        j = posed_joints(r, rot.double(), root.double())[0]
        # the bag stays behind the chest: its centre is nearer spine3 than the pelvis, and within 35 cm of it
        c = v[bag].mean(0)
        assert float((c - j[J["spine3"]]).norm()) < 0.35
        # and behind it: against the direction the body faces (left shoulder - right shoulder, x up: forward)
        fwd = torch.cross(j[J["left_shoulder"]] - j[J["right_shoulder"]], j[J["neck"]] - j[J["pelvis"]], dim=0)
        assert float(torch.dot(c - j[J["spine3"]], fwd / fwd.norm())) < -0.05


def test_exported_mesh_carries_the_accessories(tmp_path):
    import trimesh
    from splatting.rider.body import export_rider
    r = load_rider(HELMETED)
    p = export_rider(r, tmp_path / "rider.ply")
    m = trimesh.load(p, process=False)
    assert len(m.vertices) == len(r.vertices) and len(m.faces) == len(r.faces)
    helmet = (r.regions == REGIONS.index("helmet")).numpy()
    want = np.round(looks.hex_rgb(r.spec["colors"]["helmet"]) * 255)
    got = np.asarray(m.visual.vertex_colors)[helmet, :3].astype(float)
    assert (np.abs(got - want).max(1) <= 1).mean() > 0.8  # the shell in the helmet colour (vents darker)


def test_dataset_looks_recolour_hair_and_bag_per_instance_without_changing_earlier_draws():
    from splatting.cyclist import appearance
    a = {"regions": ["top", "bottom", "shoes", "helmet", "paint", "hair", "bag"], "keep_share": 0.0,
         "saturation": [0.15, 0.9], "value": [0.12, 0.95], "brightness": [0.75, 1.25], "white_balance": 0.08}
    old = dict(a, regions=["top", "bottom", "shoes", "helmet", "paint"])
    from splatting.dataset.config_models import Appearance
    a, old = Appearance(**a), Appearance(**old)
    look, gain = appearance.draw_look(a, 3, 7, 0)
    look0, gain0 = appearance.draw_look(old, 3, 7, 0)
    # the regions drawn before hair and bags existed get the same colours and gain
    assert all(np.array_equal(look[k], look0[k]) for k in ("top", "bottom", "shoes", "helmet", "paint"))
    assert np.array_equal(gain, gain0) and "hair" not in look0 and "bag" not in look0
    hairs = [appearance.draw_look(a, 3, i, 0)[0]["hair"] for i in range(20)]
    assert len({tuple(np.round(h, 4)) for h in hairs}) >= 5
    palette = np.stack([looks.hex_rgb(c) for c in looks.HAIR_COLOURS + looks.GREY_HAIR])
    for h in hairs:  # natural hair: a palette colour made 20 % darker or lighter at most
        ratio = h / palette
        assert (np.ptp(ratio, axis=1) < 1e-6).any() or np.any(h >= 1.0)
        k = int(np.argmin(np.ptp(ratio, axis=1)))
        assert 0.8 - 1e-6 <= ratio[k].mean() <= 1.2 + 1e-6


def test_hair_and_bag_recolour_only_their_gaussians():
    from splatting.cyclist import appearance
    from splatting.cyclist.assets import mesh_avatar
    from cyclist_formats.instances import RIDER_ID
    r = _with_look(RIDER, helmet=False, hair="short", bag="backpack")
    g = mesh_avatar(r).gaussians
    reg = appearance.rider_regions(g.means, r)
    refs = appearance.reference_colours(r)
    assert refs["hair"] == looks.look_of(r.spec)["hair_colour"] and "bag" in refs
    ids = torch.full((len(g),), RIDER_ID)
    for region in ("hair", "bag"):
        out = appearance.apply_look(g, ids, {region: np.array([0.9, 0.1, 0.1])}, np.ones(3), reg, refs)
        changed = ((out.sh - g.sh).abs() > 1e-5).flatten(1).any(1)
        want = reg == REGIONS.index(region)
        assert bool(want.any()) and torch.equal(changed, want), region
    bald = _with_look(RIDER, helmet=True, hair="bald", bag="none")
    assert "hair" not in appearance.reference_colours(bald) and "bag" not in appearance.reference_colours(bald)

"""Per-instance accessories (issue 28): helmet, hair style and backpack drawn per dataset instance.
A sample stays a function of (config, index); shares 0 and 1 give no / every helmet, in the avatar's
Gaussians, the record and the rendered mask; accessory sets follow their bone; with the fields at
their defaults nothing is drawn and nothing changes; trained avatars only gain what they lack."""
import json
import os

import numpy as np
import pytest
import roma
import torch

from helpers import RIDER, dataset_main, fixed_scene, small_config, street_config, write_test_bike

BARE = "f_teen_slim_150"  # its own look: buzz cut, no helmet, no bag (blend_assets/riders.yaml)
ALL_HAIR = ["bald", "buzz", "short", "long", "bun"]


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    torch.set_num_threads(1)
    r = str(tmp_path_factory.mktemp("acc_bikes"))
    write_test_bike(r)
    return r


def _cfg(raw):
    from splatting.dataset.config import resolve_assets, validate
    return resolve_assets(validate(raw))


def _sample(cfg, index):
    from splatting.dataset.generate import Assets, make_sample
    return make_sample(cfg, index, Assets(cfg))


def test_hair_styles_of_the_config_are_the_looks():
    from splatting.cyclist.look_defaults import HAIR_STYLES
    from splatting.rider import looks
    assert HAIR_STYLES == looks.HAIR_STYLES


def test_same_config_and_index_give_the_same_sample(root):
    raw = street_config(root, riders=[RIDER, BARE], appearance={"helmet_share": 0.5, "bag_share": 0.5,
                                                                 "hair_styles": ALL_HAIR})
    cfg = _cfg(raw)
    from splatting.dataset.generate import Assets, make_sample
    warm = Assets(cfg)
    make_sample(cfg, 1, warm)  # another sample first: the caches must not change sample 0
    a, b = make_sample(cfg, 0, warm), _sample(cfg, 0)
    assert np.array_equal(a[0], b[0])
    assert json.dumps(a[1], sort_keys=True) == json.dumps(b[1], sort_keys=True)
    assert json.dumps(a[2], sort_keys=True) == json.dumps(b[2], sort_keys=True)
    worn = [i["accessories"] for i in a[1]["instances"] if i["rider"] is not None]
    assert worn and all(set(w) == {"helmet", "hair", "bag"} for w in worn)
    # the draw is a function of (seed, index, instance): another seed draws other accessories
    from splatting.cyclist import accessories
    own = {"helmet": False, "hair": "buzz", "bag": "none"}
    draws = [accessories.draw(cfg.appearance, s, 0, 0, own) for s in range(40)]
    assert draws == [accessories.draw(cfg.appearance, s, 0, 0, own) for s in range(40)]
    assert len({json.dumps(d, sort_keys=True) for d in draws}) > 5


def test_shares_draw_the_share_and_leave_null_fields_as_the_rider():
    from splatting.cyclist import accessories
    from splatting.dataset.config_models import Appearance
    own = {"helmet": True, "hair": "long", "bag": "backpack"}
    a = Appearance(helmet_share=0.3)
    d = [accessories.draw(a, 0, i, k, own) for i in range(200) for k in range(3)]
    share = np.mean([x["helmet"] for x in d])
    assert 0.24 < share < 0.36
    assert all(x["hair"] == "long" and x["bag"] == "backpack" for x in d)
    d = [accessories.draw(Appearance(hair_styles=["bun", "bald"]), 0, i, 0, own)["hair"] for i in range(100)]
    assert set(d) == {"bun", "bald"}


def _one_rider(monkeypatch, root, share):
    """One rider (bald, so the skull's top is the head's top) 8 m ahead of a fixed long-focus camera."""
    fixed_scene(monkeypatch, [(RIDER, 90.0, 0.0, 8.0)])
    raw = street_config(root, labels={"formats": ["coco", "kitti"]},
                        appearance={"helmet_share": share, "bag_share": 0, "hair_styles": ["bald"]})
    raw["camera"] = {"preset": "custom", "width": 320, "height": 400, "fx": 1500, "cy": 120, "height_m": 1.4}
    raw.pop("rider_gaussians")  # every vertex: each accessory vertex is a Gaussian
    cfg = _cfg(raw)
    from splatting.dataset.generate import Assets, make_sample
    assets = Assets(cfg)
    return make_sample(cfg, 0, assets), assets


def test_helmet_share_0_and_1_give_no_and_every_helmet(monkeypatch, root):
    from splatting.rider.body import REGIONS
    out = {}
    for share in (0.0, 1.0):
        (rgb, image, anns, extras), assets = _one_rider(monkeypatch, root, share)
        rec = image["instances"][0]
        assert rec["accessories"] == {"helmet": share == 1.0, "hair": "bald", "bag": "none"}
        key = (RIDER, share == 1.0, "bald", "none")
        avatar, body = assets.model(key)
        n_helmet = int((body.regions == REGIONS.index("helmet")).sum())
        # the instance's rider Gaussians are that body's vertices: the helmet set is there or not
        assert len(avatar) == len(body.vertices)
        if share == 1.0:
            a, b = body.accessory_parts["helmet"]
            assert n_helmet == b - a > 500
        else:
            assert n_helmet == 0 and "helmet" not in body.accessory_parts
        from splatting.dataset.labels import CATEGORY_IDS
        person = next(a for a in anns if a["category_id"] == CATEGORY_IDS["rider"])
        out[share] = (rgb, person, extras["kitti"][0])
    # the helmet raises the top of the rider's box and mask (COCO) and of the KITTI box: 1.5 cm or
    # more above a bald skull, >= 2 px at 8 m here; the body below the head is the same
    top0, top1 = out[0.0][1]["bbox"][1], out[1.0][1]["bbox"][1]
    assert top1 <= top0 - 2, (top0, top1)
    assert out[1.0][2]["y1"] <= out[0.0][2]["y1"] - 2
    assert abs(out[1.0][1]["bbox"][1] + out[1.0][1]["bbox"][3] - out[0.0][1]["bbox"][1] - out[0.0][1]["bbox"][3]) < 1
    # pixels above the bald skull: background without the helmet, helmet colour with it
    rows = slice(int(top1), int(top0) - 1)
    assert not np.array_equal(out[0.0][0][rows], out[1.0][0][rows])


def test_accessory_sets_follow_their_bone():
    from splatting.cyclist import accessories
    from splatting.cyclist.assets import mesh_avatar
    from splatting.rider.kinematics import JOINT_INDEX, forward_kinematics
    from splatting.rider.roster import load_rider
    body = load_rider(BARE)
    avatar, dressed = accessories.dressed_avatar(mesh_avatar(body), body, {"helmet": True, "hair": "long",
                                                                          "bag": "backpack"}, trained=None)
    parts = dressed.accessory_parts
    assert set(parts) >= {"helmet", "hair", "ponytail", "backpack"}
    # the body is the rider's own: same vertices and weights before the accessories
    n = body.body_vertex_count
    assert torch.equal(dressed.vertices[:n], body.vertices[:n]) and torch.equal(dressed.weights[:n], body.weights[:n])
    gen = torch.Generator().manual_seed(3)
    dist = {}
    for k in range(3):
        aa = 0.5 * torch.randn(1, 24, 3, generator=gen, dtype=torch.float64)
        rot = roma.rotvec_to_rotmat(aa).float()
        root = torch.randn(1, 3, generator=gen)
        means = avatar.pose_tensors(rot, root)["means"][0]
        joints = forward_kinematics(avatar.rest_joints, rot, root)[0][0]
        head = joints[JOINT_INDEX["head"]]
        for name in ("helmet", "hair", "ponytail"):
            d = (means[slice(*parts[name])] - head).norm(dim=1)
            dist.setdefault(name, []).append((float(d.max()), d))
    for name, ds in dist.items():  # rigid on the head: every Gaussian keeps its distance to the joint
        assert max(abs(m - ds[0][0]) for m, _ in ds) < 1e-4, name
        assert all(torch.allclose(d, ds[0][1], atol=1e-4) for _, d in ds), name
    # the backpack bends with the torso: skinned on spine / pelvis joints, not on the head or arms
    w = dressed.weights[slice(*parts["backpack"])]
    torso = [JOINT_INDEX[j] for j in ("pelvis", "spine1", "spine2", "spine3")]
    assert bool(torch.isin(w.argmax(1), torch.tensor(torso)).all())
    assert float(w[:, JOINT_INDEX["head"]].max()) == 0.0
    # each takes the weights of a torso vertex of the body beneath it (the jersey's)
    body_w = body.weights[:n]
    assert all(bool((body_w == row).all(1).any()) for row in w[::97])


def test_default_fields_draw_nothing_and_change_nothing(monkeypatch, root, tmp_path):
    from splatting.cyclist import accessories
    from splatting.dataset import generate
    from splatting.dataset.command import generate as run
    from splatting.dataset.config import validate
    raw = street_config(root, riders=[BARE, RIDER], appearance={"enabled": True})
    cfg = validate(raw)
    rec = generate.config_record(cfg)
    # config.json keeps the appearance keys it had before the accessory fields existed
    assert list(rec["appearance"]) == ["enabled", "regions", "keep_share", "saturation", "value", "brightness",
                                       "white_balance"]

    def refuse(*a, **k):
        raise AssertionError("accessories drawn with the fields at their defaults")
    monkeypatch.setattr(accessories, "draw", refuse)
    monkeypatch.setattr(accessories, "swap_rider", refuse)
    out = str(tmp_path / "default")
    run(cfg, out, log=lambda m: None, progress=False)
    monkeypatch.undo()
    for f in os.listdir(os.path.join(out, "shards")):
        image = json.load(open(os.path.join(out, "shards", f)))["image"]
        assert all("accessories" not in i for i in image["instances"])
    # fields set, but every draw the rider's own look: the rendered bytes are the default's
    own = street_config(root, riders=[BARE], appearance={"enabled": True, "helmet_share": 0, "bag_share": 0,
                                                         "hair_styles": ["buzz"]})
    plain = street_config(root, riders=[BARE], appearance={"enabled": True})
    a, b = _sample(_cfg(own), 0), _sample(_cfg(plain), 0)
    assert np.array_equal(a[0], b[0])
    assert [i.pop("accessories") for i in a[1]["instances"] if i["rider"]] == \
        [{"helmet": False, "hair": "buzz", "bag": "none"}] * sum(1 for i in b[1]["instances"] if i["rider"])
    assert json.dumps(a[1], sort_keys=True) == json.dumps(b[1], sort_keys=True) and a[2] == b[2]


def _fake_trained(riders_root, rider_id, bare=False, record=True, **look):
    """A trained avatar folder for rider_id (its mesh avatar saved as rider.ply + skinning.npz, and the
    look.json `rider-avatar` writes unless not record); bare: its accessory-free base in <folder>/bare
    (what `rider-avatar --bare` trains); look: fields it was trained in other than its roster look's."""
    from splatting.cyclist.assets import mesh_avatar
    from splatting.rider.avatar_look import write_look
    from splatting.rider.body import redress
    from splatting.rider.looks import BARE
    from splatting.rider.roster import load_rider
    rider = load_rider(rider_id)
    if bare or look:
        rider = redress(rider, **(BARE if bare else look))
    av = mesh_avatar(rider, 3000)
    folder = os.path.join(riders_root, rider_id, *(["bare"] if bare else []))
    av.save(folder)
    if record:
        write_look(folder, rider)
    return av


def test_trained_avatars_gain_only_what_they_lack(root, tmp_path):
    from cyclist_formats.errors import UserError
    from splatting.cyclist import accessories
    from splatting.dataset.generate import Assets
    riders_root = str(tmp_path / "riders")
    _fake_trained(riders_root, BARE)
    _fake_trained(riders_root, RIDER)  # trained wearing a helmet, long hair and a backpack
    base = dict(riders_root=riders_root, synthetic_assets="auto")
    ok = _cfg(small_config(root, riders=[BARE], appearance={"helmet_share": 1.0, "bag_share": 1.0}, **base))
    assets = Assets(ok)
    assets.cyclist("city_t", BARE)
    trained = assets.avatars[BARE]
    key = assets.wearing(BARE, {"helmet": True, "hair": "buzz", "bag": "backpack"})
    av, body = assets.model(key)
    (h0, h1), (b0, b1) = body.accessory_parts["helmet"], body.accessory_parts["backpack"]
    assert len(av) == len(trained) + (h1 - h0) + (b1 - b0)
    assert torch.equal(av.gaussians.means[:len(trained)], trained.gaussians.means)  # the trained body as it was
    assert torch.equal(av.gaussians.means[len(trained):len(trained) + h1 - h0], body.vertices[h0:h1])
    for field, app in (("appearance.helmet_share", {"helmet_share": 0.5}), ("appearance.bag_share", {"bag_share": 0.0}),
                       ("appearance.hair_styles", {"hair_styles": ["bun"]})):
        with pytest.raises(UserError, match=field.replace(".", r"\.")):
            _cfg(small_config(root, riders=[RIDER], appearance=app, **base))
    # mesh avatars of the same rider take them all
    _cfg(small_config(root, riders=[RIDER], appearance={"helmet_share": 0.5, "bag_share": 0.0, "hair_styles": ["bun"]}))
    with pytest.raises(UserError):
        accessories.dressed_avatar(trained, assets.bodies[BARE], {"helmet": False, "hair": "bun", "bag": "none"},
                                   assets.own(BARE))


@pytest.mark.parametrize("app, field", [({"helmet_share": 1.5}, "appearance.helmet_share"),
                                        ({"bag_share": float("nan")}, "appearance.bag_share"),
                                        ({"hair_styles": ["mohawk"]}, "appearance.hair_styles"),
                                        ({"hair_styles": []}, "appearance.hair_styles")])
def test_bad_accessory_fields_name_the_field(root, app, field):
    from cyclist_formats.errors import UserError
    from splatting.dataset.config import validate
    with pytest.raises(UserError, match=field.replace(".", r"\.")):
        validate(small_config(root, appearance=app))


def test_relit_sets_refuse_accessories(root):
    from cyclist_formats.errors import UserError
    from splatting.dataset.config import validate
    with pytest.raises(UserError, match="appearance"):
        validate(small_config(root, lighting={"mode": "relit"}, appearance={"helmet_share": 0.5}))


def test_a_bare_base_takes_every_draw(root, tmp_path):
    from splatting.cyclist.appearance import dc_rgb
    from splatting.dataset.generate import Assets, make_sample
    from splatting.rider.looks import hex_rgb, look_of
    riders_root = str(tmp_path / "riders")
    _fake_trained(riders_root, RIDER)  # trained in its look: helmet, long hair, backpack
    base = _fake_trained(riders_root, RIDER, bare=True)
    raw = small_config(root, riders=[RIDER], riders_root=riders_root, synthetic_assets="auto",
                       appearance={"helmet_share": 0.5, "bag_share": 0.5, "hair_styles": ALL_HAIR})
    cfg = _cfg(raw)  # no refusal: the bare base can lose the helmet and change the hair
    assets = Assets(cfg)
    assets.cyclist("city_t", RIDER)
    n = len(base)
    for choice in ({"helmet": False, "hair": "bald", "bag": "none"}, {"helmet": False, "hair": "buzz", "bag": "none"},
                   {"helmet": True, "hair": "long", "bag": "backpack"}):
        key = assets.wearing(RIDER, choice)
        assert key != RIDER  # the bare base, even for the rider's own look
        av, body = assets.model(key)
        assert len(av) == n + sum(b - a for a, b in body.accessory_parts.values())
        assert torch.equal(av.gaussians.means[:n], base.gaussians.means)
        changed = ((av.gaussians.sh[:n] - base.gaussians.sh).abs() > 1e-6).flatten(1).any(1)
        if choice["hair"] == "bald":
            assert not bool(changed.any()) and not body.accessory_parts
        else:  # the scalp painted in the hair colour (a buzz cut; under the long hair's shell too)
            assert int(changed.sum()) > 20
            y = base.gaussians.means[changed, 1]
            assert float(y.min()) > 0.8 * body.height_m
            want = torch.tensor(hex_rgb(look_of(body.spec)["hair_colour"]), dtype=torch.float32)
            rgb = dc_rgb(av.gaussians.sh[:n][changed])
            assert float((rgb - want).abs().mean()) < 0.25
    _, image, _, _ = make_sample(cfg, 0, assets)
    assert set(image["instances"][0]["accessories"]) == {"helmet", "hair", "bag"}


def test_rider_avatar_bare_trains_the_accessory_free_look(tmp_path, monkeypatch):
    """`rider-avatar --bare`: the rest mesh Blender renders for training is the body alone (bald, no
    helmet, no bag); the steps after it are stopped here (Blender and training are not run)."""
    import trimesh
    from splatting.rider import avatar_build
    from splatting.rider.roster import load_rider

    class Stop(Exception):
        pass

    def stop(*a, **k):
        raise Stop
    monkeypatch.setattr(avatar_build, "render_views", stop)
    for bare in (False, True):
        out = str(tmp_path / f"bare_{bare}")
        with pytest.raises(Stop):
            avatar_build.build_avatar(RIDER, out, bare=bare, log=lambda m: None)
        mesh = trimesh.load(os.path.join(out, "rest_mesh.ply"), process=False)
        rider = load_rider(RIDER)
        assert len(mesh.vertices) == (rider.body_vertex_count if bare else len(rider.vertices))


def test_the_record_not_the_roster_says_what_a_trained_avatar_wears(root, tmp_path):
    """A trained avatar wears what its look.json says: trained without the backpack its roster look now
    has, it is given the backpack set when one is drawn; trained with one its roster look lacks, it is
    not given a second, and cannot lose it."""
    from cyclist_formats.errors import UserError
    from splatting.dataset.generate import Assets, make_sample
    no_bag, with_bag = str(tmp_path / "no_bag"), str(tmp_path / "with_bag")
    trained = _fake_trained(no_bag, RIDER, bag="none")  # roster: helmet, long hair, backpack
    cfg = _cfg(small_config(root, riders=[RIDER], riders_root=no_bag, synthetic_assets="auto",
                            appearance={"bag_share": 1.0}))
    assets = Assets(cfg)
    assets.cyclist("city_t", RIDER)
    assert assets.own(RIDER) == {"helmet": True, "hair": "long", "bag": "none"}
    key = assets.wearing(RIDER, {"helmet": True, "hair": "long", "bag": "backpack"})
    av, body = assets.model(key)
    b0, b1 = body.accessory_parts["backpack"]
    assert len(av) == len(trained) + b1 - b0  # the backpack set, and nothing else
    assert torch.equal(av.gaussians.means[len(trained):], body.vertices[b0:b1])
    _, image, _, _ = make_sample(cfg, 0, assets)
    assert image["instances"][0]["accessories"]["bag"] == "backpack"
    # a null bag_share keeps what the avatar wears (no backpack), not the roster's backpack
    cfg = _cfg(small_config(root, riders=[RIDER], riders_root=no_bag, synthetic_assets="auto",
                            appearance={"helmet_share": 1.0}))
    _, image, _, _ = make_sample(cfg, 0, Assets(cfg))
    assert image["instances"][0]["accessories"] == {"helmet": True, "hair": "long", "bag": "none"}

    trained = _fake_trained(with_bag, BARE, bag="backpack")  # roster: buzz cut, no helmet, no bag
    cfg = _cfg(small_config(root, riders=[BARE], riders_root=with_bag, synthetic_assets="auto",
                            appearance={"bag_share": 1.0}))
    assets = Assets(cfg)
    assets.cyclist("city_t", BARE)
    assert assets.wearing(BARE, {"helmet": False, "hair": "buzz", "bag": "backpack"}) == BARE
    _, image, _, _ = make_sample(cfg, 0, assets)
    assert image["instances"][0]["accessories"]["bag"] == "backpack"
    assert len(assets.avatars[BARE]) == len(trained)  # its own Gaussians: no second backpack
    with pytest.raises(UserError, match=r"appearance\.bag_share"):  # the back under it was never seen
        _cfg(small_config(root, riders=[BARE], riders_root=with_bag, synthetic_assets="auto",
                          appearance={"bag_share": 0.5}))


def test_an_avatar_without_a_record_is_refused_when_accessories_are_drawn(root, tmp_path):
    """A trained avatar without look.json (built before avatars recorded their look, as the demo's):
    with accessory fields set the dataset refuses it before any work, in one line naming its folder
    and the command that rebuilds it; with the fields null it renders as before (the record unread)."""
    import shutil
    from splatting.rider.avatar_look import LOOK_NAME
    riders_root = str(tmp_path / "riders")
    _fake_trained(riders_root, RIDER, record=False)
    folder = os.path.join(riders_root, RIDER)
    raw = small_config(root, riders=[RIDER], riders_root=riders_root, synthetic_assets="auto", count=1)
    for app in ({"helmet_share": 1.0}, {"bag_share": 1.0}, {"hair_styles": ["long"]}):
        rc, msg = dataset_main(dict(raw, appearance=app), tmp_path)
        assert rc != 0 and len(msg.splitlines()) == 1, msg
        assert folder in msg and LOOK_NAME in msg and f"rider-avatar --id {RIDER} --out {folder}" in msg, msg
        assert not os.path.exists(tmp_path / "o")
    _fake_trained(riders_root, RIDER, bare=True, record=False)  # a bare base without one: the same
    rc, msg = dataset_main(dict(raw, appearance={"helmet_share": 0.5}), tmp_path)
    assert rc != 0 and len(msg.splitlines()) == 1 and f"--bare --out {os.path.join(folder, 'bare')}" in msg, msg
    shutil.rmtree(os.path.join(folder, "bare"))
    # fields null: it works, and renders what the same avatar with a record renders
    with_record = str(tmp_path / "with_record")
    shutil.copytree(riders_root, with_record)
    from splatting.rider.avatar_look import write_look
    from splatting.rider.roster import load_rider
    write_look(os.path.join(with_record, RIDER), load_rider(RIDER))
    a = _sample(_cfg(raw), 0)
    b = _sample(_cfg(dict(raw, riders_root=with_record)), 0)
    assert "accessories" not in a[1]["instances"][0]
    assert np.array_equal(a[0], b[0]) and json.dumps(a[1], sort_keys=True) == json.dumps(b[1], sort_keys=True)
    assert a[0].std() > 0


def test_dressed_riders_are_evicted_and_rebuilt_identically(root):
    """The dressed-rider cache holds DRESSED_CACHE riders over all riders; the least recently used one
    goes (with what was computed of it), and drawn again it is rebuilt to the same Gaussians."""
    import itertools
    from cyclist_formats.instances import RIDER_ID
    from splatting.dataset import generate
    from splatting.dataset.generate import Assets
    cfg = _cfg(small_config(root, riders=[RIDER, BARE], appearance={"helmet_share": 0.5}))
    assets = Assets(cfg)
    keys = []
    for rider in (RIDER, BARE):
        assets.cyclist("city_t", rider)
        for helmet, hair, bag in itertools.product((True, False), ("bald", "bun"), ("none", "backpack")):
            keys.append(assets.wearing(rider, {"helmet": helmet, "hair": hair, "bag": bag}))
            if len(keys) == 1:
                first = assets.dressed(keys[0])
                g = first.avatar.gaussians
                assets.lod_order("city_t", keys[0], g, torch.full((len(g),), RIDER_ID))
                assert first.derived  # the lod ranking lives with the dressed rider
    assert len(set(keys)) > generate.DRESSED_CACHE and all(isinstance(k, tuple) for k in keys)
    info = assets.dressed.cache_info()
    assert info.maxsize == generate.DRESSED_CACHE == info.currsize
    again = assets.dressed(keys[0])
    assert again is not first and not again.derived  # evicted, with its ranking, then rebuilt
    assert assets.dressed.cache_info().misses == info.misses + 1
    a, b = first.avatar, again.avatar
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        assert torch.equal(getattr(a.gaussians, name), getattr(b.gaussians, name)), name
    assert torch.equal(a.weights, b.weights) and torch.equal(first.body.vertices, again.body.vertices)
    assert assets.dressed(keys[0]) is again  # and cached again


def test_rider_avatar_records_the_look_it_trains(tmp_path, monkeypatch):
    """`rider-avatar` writes look.json before the rest mesh: the look the views are rendered in (bare:
    looks.BARE); a folder holding a build of another look is refused before any work; one built before
    the record existed is resumed without a record (its look is unknown: no guess)."""
    from cyclist_formats.errors import UserError
    from splatting.rider import avatar_build
    from splatting.rider.avatar_look import LOOK_NAME, read_look
    from splatting.rider.looks import BARE, look_of
    from splatting.rider.roster import get_spec

    class Stop(Exception):
        pass

    def stop(*a, **k):
        raise Stop
    monkeypatch.setattr(avatar_build, "render_views", stop)
    own = look_of(get_spec(RIDER))
    for bare in (False, True):
        out = str(tmp_path / f"bare_{bare}")
        with pytest.raises(Stop):
            avatar_build.build_avatar(RIDER, out, bare=bare, log=lambda m: None)
        rec = read_look(out)
        assert rec == {"rider": RIDER, "look": dict(own, **BARE) if bare else own}
    dressed = str(tmp_path / "bare_False")
    mesh = os.path.join(dressed, "rest_mesh.ply")
    before = os.stat(mesh).st_mtime_ns
    with pytest.raises(UserError, match="another look"):  # --bare into a dressed build: not skipped through
        avatar_build.build_avatar(RIDER, dressed, bare=True, log=lambda m: None)
    assert os.stat(mesh).st_mtime_ns == before and read_look(dressed)["look"] == own
    os.remove(os.path.join(dressed, LOOK_NAME))  # a build from before the records
    logs = []
    with pytest.raises(Stop):
        avatar_build.build_avatar(RIDER, dressed, log=logs.append)
    assert not os.path.exists(os.path.join(dressed, LOOK_NAME)) and any(LOOK_NAME in m for m in logs)
    with open(os.path.join(dressed, LOOK_NAME), "w") as f:
        f.write('{"rider": 3}')
    with pytest.raises(UserError, match=LOOK_NAME):  # a corrupt record is not taken for a missing one
        avatar_build.build_avatar(RIDER, dressed, log=lambda m: None)

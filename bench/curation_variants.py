"""Write one transformed copy of a model, as real files come (bench/curation_stress.py's inputs).

    .venv/bin/python -m bench.curation_variants --input MODEL --variant NAME --out FILE

Runs on the bpy side: imports MODEL with the curation's own importer, applies the variant to the
whole scene (every root object parented to one transform, so hierarchies, skins and instancing
move together) or to its meshes (joined, decimated), and exports FILE with the exporter of
FILE's extension (.glb, .fbx, .obj).  Variants (VARIANTS): which axis is up, a yaw about up, the
file's unit (x0.01, x100), the origin far away, all meshes joined, half the faces, mirrored, and
the plain round trips through glTF, FBX and OBJ (their exporters' own conventions: FBX's and
OBJ's Y-up axis conversion and unit scale).
"""
import argparse
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

# name -> (whole-scene transform as (rotation axis, degrees) / scale / offset, mesh edit, export extension)
VARIANTS = {
    "glb": {"ext": ".glb"},                                  # control: the exporter alone
    "z_up": {"rot": ("X", 90.0), "ext": ".glb"},            # a Z-up model written as if Y-up: lying on its side
    "yaw37": {"rot": ("Z", 37.0), "ext": ".glb"},
    "yaw143": {"rot": ("Z", 143.0), "ext": ".glb"},
    "yaw251": {"rot": ("Z", 251.0), "ext": ".glb"},
    "scale0.01": {"scale": 0.01, "ext": ".glb"},
    "scale100": {"scale": 100.0, "ext": ".glb"},
    "far": {"offset": (50.0, 50.0, 0.0), "ext": ".glb"},
    "joined": {"mesh": "join", "ext": ".glb"},
    "decimated": {"mesh": "decimate", "ext": ".glb"},
    "mirrored": {"mirror": True, "ext": ".glb"},
    "fbx": {"ext": ".fbx"},
    "obj": {"ext": ".obj"},
}


def _whole_scene(bpy, spec):
    from mathutils import Matrix

    m = Matrix.Identity(4)
    if "rot" in spec:
        axis, deg = spec["rot"]
        m = Matrix.Rotation(math.radians(deg), 4, axis)
    if "scale" in spec:
        m = Matrix.Scale(spec["scale"], 4) @ m
    if spec.get("mirror"):
        m = Matrix.Scale(-1.0, 4, (1.0, 0.0, 0.0)) @ m
    if "offset" in spec:
        m = Matrix.Translation(spec["offset"]) @ m
    if m == Matrix.Identity(4):
        return
    root = bpy.data.objects.new("stress_root", None)
    bpy.context.scene.collection.objects.link(root)
    for o in list(bpy.context.scene.objects):
        if o is not root and o.parent is None:
            o.parent = root            # root at identity: world matrices unchanged
    root.matrix_world = m


def _meshes(bpy, how):
    ctx = bpy.context
    meshes = [o for o in ctx.scene.objects if o.type == "MESH" and o.visible_get()]
    if how == "decimate":
        for o in meshes:
            mod = o.modifiers.new("stress_decimate", "DECIMATE")
            mod.ratio = 0.5
        return
    bpy.ops.object.select_all(action="DESELECT")
    for o in meshes:
        o.select_set(True)
    ctx.view_layer.objects.active = meshes[0]
    bpy.ops.object.convert(target="MESH")          # modifiers (skins) applied, shared data made single
    bpy.ops.object.join()


def write(model, variant, out):
    import bpy

    from addon.core.curation import importers
    from addon.core.scene import reset_scene

    spec = VARIANTS[variant]
    reset_scene()
    importers.import_model(model)
    if spec.get("mesh"):
        _meshes(bpy, spec["mesh"])
    _whole_scene(bpy, spec)
    bpy.context.view_layer.update()
    tmp = out + ".tmp" + spec["ext"]
    if spec["ext"] == ".glb":
        # what the author shows: hidden helpers stay out, and an armature's joints are written at
        # the pose the scene shows (the exporter's default writes its rest pose as the nodes'
        # transforms: with the animation left out, a rigged bike's bone-parented pieces would
        # lie scattered in the file itself, for every glTF viewer, not just for the curation)
        bpy.ops.export_scene.gltf(filepath=tmp, export_format="GLB", export_apply=True, export_animations=False,
                                  export_rest_position_armature=False, export_current_frame=True, use_visible=True)
    elif spec["ext"] == ".fbx":
        bpy.ops.export_scene.fbx(filepath=tmp, use_mesh_modifiers=True, bake_anim=False, use_visible=True)
    else:
        for o in bpy.context.scene.objects:   # what the author shows: hidden helpers stay out
            o.select_set(o.visible_get())
        bpy.ops.wm.obj_export(filepath=tmp, apply_modifiers=True, export_animation=False, export_selected_objects=True)
        mtl = os.path.splitext(tmp)[0] + ".mtl"
        if os.path.isfile(mtl):          # the .obj names its .mtl: keep the pair's names together
            os.replace(mtl, os.path.splitext(out)[0] + ".mtl")
            with open(tmp) as f:
                text = f.read().replace(os.path.basename(mtl), os.path.basename(os.path.splitext(out)[0] + ".mtl"))
            with open(tmp, "w") as f:
                f.write(text)
    os.replace(tmp, out)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.curation_variants", description=__doc__.splitlines()[0])
    ap.add_argument("--input", required=True, help="model file the curation reads")
    ap.add_argument("--variant", required=True, choices=sorted(VARIANTS))
    ap.add_argument("--out", required=True, help="file to write (extension as the variant's: .glb .fbx .obj)")
    a = ap.parse_args(argv)
    if not os.path.isfile(a.input):
        ap.exit(2, f"curation_variants: error: model file not found: {a.input}\n")
    if os.path.splitext(a.out)[1].lower() != VARIANTS[a.variant]["ext"]:
        ap.exit(2, f"curation_variants: error: {a.variant} writes {VARIANTS[a.variant]['ext']}, not {a.out}\n")
    write(os.path.abspath(a.input), a.variant, os.path.abspath(a.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())

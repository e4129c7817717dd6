"""Turn a rigged human (.glb/.gltf/.fbx/.blend) into an imported-rider file (rider.npz, cyclist_formats.rider_file).

    python blender_scripts/import_rider.py --model PERSON.glb --id NAME --out DIR/rider.npz [--height-m 1.8]
    blender -b -P blender_scripts/import_rider.py -- --model PERSON.fbx --id NAME --out DIR/rider.npz

The Blender half of `python -m splatting rider import` (addon/core/rider/rider_rig.py does the work): bones
mapped to the 24 SMPL joints, rest pose turned into the T-pose, skinning weights and texture colours
carried over.  Unrigged meshes, non-humanoid rigs and missing textures end in one error line, exit 2,
and nothing written.  Prints one JSON line {"rider": OUT, ...} on success.
"""
import argparse
import contextlib
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import UserError, run_main  # noqa: E402

MODEL_EXTENSIONS = (".glb", ".gltf", ".vrm", ".fbx", ".blend")  # .vrm: a VRoid/VRM avatar, a .glb


def _numpy_aliases_for_old_gltf_importer():
    """Blender 3.4's glTF importer still uses np.bool, which numpy 1.24 removed (Debian's Blender runs
    on the system numpy 1.24): restore the alias to the builtin it always meant, for this process only."""
    import bpy
    import numpy as np
    if bpy.app.version < (3, 6, 0) and "bool" not in np.__dict__:
        np.bool = bool


@contextlib.contextmanager
def _as_importable(path):
    """A .vrm (VRoid, VRM avatars) is a binary glTF under another name: imported through a .glb link."""
    if not path.lower().endswith(".vrm"):
        yield path
        return
    with tempfile.TemporaryDirectory() as d:
        link = os.path.join(d, os.path.splitext(os.path.basename(path))[0] + ".glb")
        os.symlink(os.path.abspath(path), link)
        yield link


def main(argv):
    p = argparse.ArgumentParser(prog="import_rider.py", description=__doc__.splitlines()[0])
    p.add_argument("--model", required=True, help="rigged human: " + " ".join(MODEL_EXTENSIONS))
    p.add_argument("--id", required=True, help="the rider id it gets")
    p.add_argument("--out", required=True, help="rider file to write (.npz)")
    p.add_argument("--height-m", type=float, default=None,
                   help="scale the body to this soles-to-crown height (default: keep the file's size)")
    args = p.parse_args(argv)
    from cyclist_formats import checks
    checks.input_file("model", args.model)
    if not args.model.lower().endswith(MODEL_EXTENSIONS):
        raise UserError(f"--model must be one of {', '.join(MODEL_EXTENSIONS)}, got {args.model}")
    checks.number("height_m", args.height_m, 0.5, 2.6)
    checks.output_file("out", args.out, (".npz",))
    from addon.core.contract import gltf_extensions, rider_file
    gltf_extensions.check_readable(args.model)
    rider_file.check_rider_id(args.id)

    from addon.core.rider import rider_rig
    from addon.core.curation.importers import import_model
    from addon.core.scene import reset_scene

    _numpy_aliases_for_old_gltf_importer()
    reset_scene()
    with _as_importable(args.model) as model:
        objects = import_model(model)
    arrays, meta = rider_rig.rider_from_objects(objects, args.id, os.path.basename(args.model), args.height_m,
                                                model_dir=os.path.dirname(os.path.abspath(args.model)))
    rider_file.write_rider_file(args.out, meta=meta, **arrays)
    print(json.dumps({"rider": args.out, "vertices": len(arrays["vertices"]), "scheme": meta["scheme"],
                      "rest_pose": meta["rest_pose"], "height_m": meta["height_m"],
                      "textures": len(meta["textures"]), "missing_textures": meta["missing_textures"],
                      "size": meta["size"], "placed_joints": sorted(meta["placed_joints"]),
                      "assumed_texture": meta["assumed_texture"]}), flush=True)
    return 0


if __name__ == "__main__":
    run_main(main, "import_rider.py")

"""`python -m splatting rider import --model PERSON.glb|.fbx --id NAME`: a user's rigged human becomes a roster rider.

Runs blender_scripts/import_rider.py (the bpy module of this Python, or a Blender binary given with
--blender) which writes data/imported_riders/NAME/rider.npz; from then on `rider --list`,
`rider-avatar --id NAME`, the IK and the datasets know NAME like the built-in riders (docs/rider_import.md).
"""
import json
import os
import subprocess
import sys
import tempfile

from cyclist_formats import checks
from cyclist_formats.errors import UserError
from cyclist_formats.rider_file import check_rider_id
from splatting import paths

# The stage's modules are imported inside the functions below, not at the top: they load torch
# (~2.5 s, python -X importtime), and `--help` and the argument checks answer before that (0.2-0.5 s).

SCRIPT = paths.blender_script("import_rider.py")
MODEL_EXTENSIONS = (".glb", ".gltf", ".vrm", ".fbx", ".blend")  # .vrm: a VRoid/VRM avatar, a .glb


def add_arguments(p):
    p.add_argument("--model", required=True, help="the rigged human: " + ", ".join(MODEL_EXTENSIONS) +
                   " (an armature with Mixamo, Rigify DEF- or similar bone names; T- or A-pose)")
    p.add_argument("--id", required=True, help="rider id to give it (letters, digits, _ . -)")
    p.add_argument("--out", help="rider file to write (default data/imported_riders/ID/rider.npz, "
                                 "where the roster finds it)")
    p.add_argument("--height-m", type=float, default=None,
                   help="scale the body to this height in metres (default: the file's own size)")
    p.add_argument("--blender", default=None,
                   help="a Blender binary to run the import in (`blender -b -P`); default: the bpy module "
                        "of this Python")
    p.add_argument("--force", action="store_true", help="replace an earlier import with this id")


def check_args(args):
    checks.input_file("model", args.model)
    if not args.model.lower().endswith(MODEL_EXTENSIONS):
        raise UserError(f"--model must be one of {', '.join(MODEL_EXTENSIONS)}, got {args.model}")
    check_rider_id(args.id)
    checks.number("height_m", args.height_m, 0.5, 2.6)
    checks.output_file("out", args.out, (".npz",))
    from cyclist_formats import gltf_meshopt
    from cyclist_formats.gltf_extensions import check_readable
    check_readable(args.model, gltf_meshopt.MESHOPT if gltf_meshopt.decoder() is not None else ())
    if args.blender is not None:
        checks.input_file("blender", args.blender)


def blender_command(model, rider_id, out, height_m=None, blender=None):
    tail = ["--model", os.path.abspath(model), "--id", rider_id, "--out", os.path.abspath(out)]
    if height_m is not None:
        tail += ["--height-m", repr(float(height_m))]
    if blender:
        return [blender, "-b", "--factory-startup", "-P", SCRIPT, "--"] + tail
    return [sys.executable, SCRIPT] + tail


def without_meshopt(model, tmp, log=print):
    """The model itself, or where it needs meshopt decoding (which Blender's importer cannot do), a
    self-contained .glb of the same name in `tmp` written without it (cyclist_formats/gltf_meshopt.py)."""
    from cyclist_formats import gltf_extensions, gltf_meshopt
    used = {e for e, _ in gltf_extensions.unreadable_extensions(model)} & set(gltf_meshopt.MESHOPT)
    if not used:
        return model
    out = os.path.join(tmp, os.path.splitext(os.path.basename(model))[0] + ".glb")
    log(f"rider import: decoding {', '.join(sorted(used))} (meshoptimizer)", flush=True)
    return gltf_meshopt.decompress(model, out)


def import_rider(model, rider_id, out=None, height_m=None, blender=None, force=False, log=print):
    """Run the Blender side; returns its summary dict. UserError (its one line) when it refuses."""
    from splatting.rider.imported import rider_path
    from splatting.rider.roster import load_roster
    if any(r["id"] == rider_id for r in load_roster()):
        raise UserError(f"--id {rider_id!r} is a built-in roster rider; pick another id")
    out = os.fspath(out or rider_path(rider_id))
    if os.path.exists(out) and not force:
        raise UserError(f"{out} exists (rider {rider_id!r} was imported before): give --force to replace it")
    with tempfile.TemporaryDirectory() as tmp:
        readable = without_meshopt(model, tmp, log)
        cmd = blender_command(readable, rider_id, out, height_m, blender)
        log(f"rider import: reading {model} in Blender ({os.path.basename(cmd[0])})", flush=True)
        r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0 or not os.path.isfile(out):
        lines = [ln for ln in r.stderr.strip().splitlines() if ln.strip()]
        why = next((ln.split("error: ", 1)[1] for ln in reversed(lines) if "import_rider.py: error: " in ln),
                   lines[-1] if lines else f"exit {r.returncode}")
        raise UserError(why)
    summary = next((json.loads(ln) for ln in reversed(r.stdout.splitlines()) if ln.startswith('{"rider"')), {})
    return dict(summary, rider=out)


def run(args):
    from splatting.rider.imported import rider_path
    res = import_rider(args.model, args.id, args.out, args.height_m, args.blender, args.force)
    where = "" if os.path.abspath(res["rider"]) == os.path.abspath(rider_path(args.id)) else \
        f"; not in the roster: move it to {rider_path(args.id)}"
    print(f"{res['rider']}: rider {args.id} imported ({res.get('vertices', '?')} vertices, "
          f"{res.get('scheme', '?')} rig, {res.get('rest_pose', '?')}-pose rest, {res.get('height_m', '?')} m, "
          f"{res.get('textures', 0)} texture(s)){where}")
    print(f"  size: {res.get('size', '?')}")
    if res.get("placed_joints"):
        print(f"  joints placed from their neighbours (no bone): {', '.join(res['placed_joints'])}")
    if res.get("assumed_texture"):
        print(f"note: the model's materials reference no texture; {res['assumed_texture']}, the one image beside it, "
              f"is taken as its colour")
    for m in res.get("missing_textures") or []:
        print(f"warning: texture not found, flat base colour used: {m}", file=sys.stderr)
    return 0

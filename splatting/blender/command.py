"""`python -m splatting blender STAGE [--blender PATH] [--] ARGS`: the Blender stages of the pipeline.

Each stage is a script of blender_scripts/ that runs both as `python blender_scripts/X.py ARGS` (the
bpy module of this Python) and as `blender -b -P blender_scripts/X.py -- ARGS` (a Blender binary).
This module starts it the first way, or the second with `--blender PATH`, and hands back its exit
code; its stdout and stderr are this process's, so its one-line errors and progress lines pass
through as they are.  The script parses ARGS itself (`--help` prints its flags).  Nothing here
imports bpy: splatting stays importable without Blender.
"""
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass

from splatting import paths

PROG = "python -m splatting blender"


@dataclass(frozen=True)
class Stage:
    script: str  # file name in blender_scripts/
    help: str  # one line for `python -m splatting --help`
    needs_blender: bool = True  # False: a plain Python step (no scene), --blender refused

    @property
    def name(self):
        return os.path.splitext(self.script)[0].replace("_", "-")

    def command_line(self, args, blender=None):
        """The process to start: this Python with the bpy module, or `BLENDER -b -P script -- args`."""
        script = paths.blender_script(self.script)
        if blender:
            return [blender, "-b", "--factory-startup", "-P", script, "--"] + list(args)
        return [sys.executable, script] + list(args)

    def main(self, argv):
        """Run the stage with argv (the script's own flags; `--blender PATH` and a leading `--` are ours)."""
        prog = f"{PROG} {self.name}"
        try:
            blender, args = split_blender(argv)
            if blender is not None:
                if not self.needs_blender:
                    raise ValueError(f"{self.script} is a plain Python step; it takes no --blender")
                blender = find_blender(blender)
        except ValueError as e:
            sys.stderr.write(f"{prog}: error: {e}\n")
            return 2
        if "-h" in args or "--help" in args:
            print(f"{prog} [--blender PATH] [--] ARGS: runs blender_scripts/{self.script} "
                  f"({'in the Blender binary PATH, ' if self.needs_blender else ''}default: this Python"
                  f"{' with the bpy module' if self.needs_blender else ''}); its flags:\n", flush=True)
        try:
            return subprocess.run(self.command_line(args, blender)).returncode
        except KeyboardInterrupt:
            sys.stderr.write(f"{prog}: interrupted\n")
            return 130


STAGES = {s.name: s for s in (
    Stage("make_bikes.py", "the procedural bike library: OUT/bikes/<bike_id>/ (bike.blend, keypoints.json, meta.json)"),
    Stage("curate.py", "an imported bicycle model (.glb .obj .fbx ...) curated into a bike folder"),
    Stage("add_sub_parts.py", "a bike folder's wheels and pedals cut out as sub-parts that spin and stay level"),
    Stage("render_views.py", "a bike's parts (and the whole bike) rendered from the 36-view ring"),
    Stage("render_pose.py", "the ground-truth oracle: a bike's mesh posed with the 8-DoF pose and rendered"),
    Stage("export_bike.py", "a bike folder as an articulated URDF or glTF 2.0 model"),
    Stage("import_splats.py", "3DGS .ply Gaussians into a Blender scene, optionally rendered with Cycles"),
    Stage("import_rider.py", "a rigged human into an imported-rider file (the Blender half of `rider import`)"),
    Stage("render_rider.py", "a rider mesh rendered from the ring, one camera, or a batch of stills"),
    Stage("render_rider_on_bike.py", "imported riders posed on a bike by the IK, rendered with the bike"),
    Stage("build_addon.py", "the Blender add-on zip (dist/articcyclists-<version>.zip), validated", needs_blender=False),
)}


def split_blender(argv):
    """(--blender value or None, the script's arguments): `--blender PATH` / `--blender=PATH` before a
    `--`, which is dropped (the scripts take no --blender of their own)."""
    argv, blender, out = list(argv), None, []
    while argv:
        a = argv.pop(0)
        if a == "--":
            out += argv
            break
        if a == "--blender" or a.startswith("--blender="):
            if a == "--blender" and not argv:
                raise ValueError("--blender needs a Blender binary (PATH)")
            blender = argv.pop(0) if a == "--blender" else a.split("=", 1)[1]
            continue
        out.append(a)
    return blender, out


def find_blender(blender):
    """The Blender binary's path: an executable file, or a command name found on PATH."""
    found = shutil.which(blender) if os.sep not in blender else (blender if os.access(blender, os.X_OK) and
                                                                 os.path.isfile(blender) else None)
    if found is None:
        raise ValueError(f"--blender {blender}: no such executable (give the Blender binary, e.g. /usr/bin/blender)")
    return found


def list_stages(argv):
    """`python -m splatting blender [--help]`: the stages, one a line; a stage it does not know: one line."""
    if argv and argv[0] not in ("-h", "--help"):
        sys.stderr.write(f"{PROG}: error: no Blender stage {argv[0]!r} (one of {', '.join(STAGES)})\n")
        return 2
    print(f"usage: {PROG} STAGE [--blender PATH] [--] ARGS   (STAGE --help: its flags)\n\nBlender stages:")
    width = max(map(len, STAGES))
    for name, s in STAGES.items():
        print(f"  {name:<{width}}  {s.help}")
    return 0

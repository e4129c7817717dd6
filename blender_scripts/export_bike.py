"""Export a bike folder as an articulated model for simulators and engines: URDF or glTF 2.0.

    blender -b -P blender_scripts/export_bike.py -- --bike OUT/bikes/ID --format urdf --out DIR
    .venv/bin/python blender_scripts/export_bike.py --bike OUT/bikes/ID --format gltf --out FILE.glb

urdf: DIR/<bike_id>.urdf + DIR/meshes/{frame,steering,crank}.obj|.mtl + DIR/keypoints.json;
links frame/steering/crank, a revolute steering joint (+-limit) about the steering axis and a
continuous crank joint; inertials from each part's mesh volume at --density.  gltf: one .glb with
part nodes pivoting on the steering axis and the crank axle, keypoint nodes and a clip
`pedal_steer`.  See docs/export.md for the frames and conventions.
"""
import argparse
import math
import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import UserError, run_main  # noqa: E402

DEFAULT_DENSITY = 1000.0  # kg/m^3: the parts are solid meshes of hollow tubes; ~10 kg for a road bike


def parse(argv):
    p = argparse.ArgumentParser(prog="export_bike.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--bike", required=True, help="bike folder (bike.blend, keypoints.json, meta.json)")
    p.add_argument("--format", required=True, choices=["urdf", "gltf"])
    p.add_argument("--out", required=True, help="urdf: output folder (replaced); gltf: output .glb file")
    p.add_argument("--density", type=float, default=DEFAULT_DENSITY,
                   help=f"kg/m^3 for the URDF inertials (default {DEFAULT_DENSITY:g})")
    p.add_argument("--steer-limit-deg", type=float, default=90.0,
                   help="URDF steering joint limit +-deg (default 90, the add-on's slider range)")
    p.add_argument("--clip-seconds", type=float, default=2.0, help="glTF clip length: one crank turn (default 2)")
    p.add_argument("--clip-steer-deg", type=float, default=20.0,
                   help="glTF clip steering amplitude, theta_s = A sin(2 pi t / T) (default 20)")
    args = p.parse_args(argv)
    for name in ("density", "clip_seconds"):
        v = getattr(args, name)
        if not (math.isfinite(v) and v > 0):
            raise UserError(f"--{name.replace('_', '-')} must be a positive number, got {v}")
    if not (math.isfinite(args.steer_limit_deg) and 0 < args.steer_limit_deg <= 180):
        raise UserError(f"--steer-limit-deg must be in (0, 180], got {args.steer_limit_deg}")
    if not (math.isfinite(args.clip_steer_deg) and abs(args.clip_steer_deg) <= 180):
        raise UserError(f"--clip-steer-deg must be in [-180, 180], got {args.clip_steer_deg}")
    if args.format == "gltf" and not args.out.lower().endswith(".glb"):
        raise UserError(f"--out must name a .glb file for --format gltf, got {args.out}")
    if args.format == "urdf" and os.path.exists(args.out) and not os.path.isdir(args.out):
        raise UserError(f"--out {args.out} exists and is not a folder")
    return args


def main(argv):
    args = parse(argv)
    from addon.core.export import gltf, parts, urdf

    bike_dir = os.path.abspath(args.bike)
    rig, meta = parts.check_bike_folder(bike_dir)  # before Blender opens anything
    name = str(meta.get("bike_id") or os.path.basename(bike_dir.rstrip("/")))
    t0 = time.time()
    meshes = parts.load_part_meshes(bike_dir, rig.parts)
    print(f"export_bike: read {', '.join(f'{p} {len(m.tris)} tris' for p, m in meshes.items())} "
          f"({time.time() - t0:.1f} s)", flush=True)
    out = os.path.abspath(args.out)
    if args.format == "gltf":
        from cyclist_formats.atomic import write_bytes

        data = gltf.build(rig, meshes, name, args.clip_seconds, math.radians(args.clip_steer_deg))
        write_bytes(out, data)
        print(f"export_bike: {out} ({len(data) / 1e6:.2f} MB)")
        return 0
    try:
        text, files, kp, masses = urdf.build(rig, meshes, args.density, math.radians(args.steer_limit_deg), name,
                                             hull=parts.convex_hull)
    except ValueError as e:
        raise UserError(f"{bike_dir}: cannot compute the inertials: {e}")
    for p, mp in masses.items():
        print(f"export_bike: {p}: {mp.volume * 1e3:.3f} L, {mp.mass:.3f} kg at {args.density:g} kg/m^3, "
              f"{mp.shells} closed shells" + (f", {mp.open_shells} open shells as convex hulls" if mp.open_shells else ""),
              flush=True)
    parent = os.path.dirname(out)
    os.makedirs(parent, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix="." + os.path.basename(out) + ".", suffix=".tmp", dir=parent)
    try:  # write everything beside the target, then swap it in: no half-written folder
        urdf.write(tmp, name, text, files, kp)
        os.chmod(tmp, 0o755)
        old = None
        if os.path.isdir(out):
            old = tempfile.mkdtemp(prefix="." + os.path.basename(out) + ".", suffix=".old", dir=parent)
            os.rmdir(old)
            os.replace(out, old)
        os.replace(tmp, out)
        if old:
            shutil.rmtree(old)
    finally:
        if os.path.isdir(tmp):
            shutil.rmtree(tmp)
    print(f"export_bike: {os.path.join(out, name + '.urdf')}")
    return 0


if __name__ == "__main__":
    run_main(main, "export_bike.py")

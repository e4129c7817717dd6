"""Import 3DGS .ply Gaussians into Blender as Gaussians, optionally render them with Cycles.

    blender -b -P blender_scripts/import_splats.py -- --ply FILE.ply [--render FILE.png] [--save FILE.blend]
    python blender_scripts/import_splats.py --ply FILE.ply --render out.png [--mode gaussian|preview]

--mode gaussian (default): Gaussians with their falloff and view-dependent SH colour on
rectangles that turn to the camera, for any camera; --mode camera: camera-facing quads that
draw what our rasterizer draws, for the render camera only (docs/import_splats.md); --mode
preview: one sphere per Gaussian (fast, DC colour only).

--ply also takes a folder or a glob of per-frame .ply files: they import as frames 1..N and
--render writes FILE_00001.png ... (or only --frame N, to FILE).  The camera is ring view 3 of
docs/contract.md's 36-view ring around the clouds' bounding-box centre, or --camera cameras.json:cameraNNNN.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from addon.core.script import UserError, run_main  # noqa: E402


def frame_path(out, frame):
    base, ext = os.path.splitext(out)
    return f"{base}_{frame:05d}{ext or '.png'}"


def main(argv):
    p = argparse.ArgumentParser(prog="import_splats.py", description=__doc__.splitlines()[0])
    p.add_argument("--ply", required=True, help="a 3DGS .ply, a folder of them, or a glob (sequence)")
    p.add_argument("--render", help="output RGBA .png (a sequence writes FILE_%%05d.png per frame)")
    p.add_argument("--save", help="save the scene to this .blend")
    p.add_argument("--frame", type=int, help="render only this frame of a sequence, to --render as given")
    p.add_argument("--camera", help="cameras.json:cameraNNNN (or a JSON file with one K/R/T); default ring view --view")
    p.add_argument("--view", type=int, default=3, help="ring view index 0..35 (default 3)")
    p.add_argument("--size", type=int, default=512, help="image size for the ring camera (default 512)")
    p.add_argument("--samples", type=int, default=None)
    p.add_argument("--denoise", choices=["NONE", "FAST", "BALANCED", "HIGH"], default=None)
    p.add_argument("--mode", choices=["gaussian", "camera", "preview"], default="gaussian",
                   help="gaussian: Gaussian falloff, SH colour, any camera (default); camera: "
                        "camera-facing quads that draw what our rasterizer draws, for the render camera only; "
                        "preview: spheres")
    p.add_argument("--sh-degree", type=int, choices=[0, 1, 2, 3], default=3,
                   help="gaussian and camera modes: highest SH degree evaluated (default 3, or the file's)")
    p.add_argument("--eps2d", type=float, default=0.3,
                   help="the screen-space low-pass (px^2) the Gaussians were trained with (default 0.3)")
    p.add_argument("--antialiased", action="store_true",
                   help="gaussian and camera modes: the Gaussians were trained with the mip filter (opacity compensation)")
    p.add_argument("--shading", choices=["emission", "lit"], default="emission",
                   help="preview mode: emission = the Gaussians' own (baked) colour; lit = Principled BSDF under the studio lights")
    p.add_argument("--radius-scale", type=float, default=None,
                   help="preview mode: sphere radius = this * sqrt(product of the two largest scales) (default sqrt 2)")
    args = p.parse_args(argv)
    from cyclist_formats import checks
    checks.image_size("size", args.size, lo=8)
    checks.count("samples", args.samples, hi=1 << 16)
    checks.output_file("render", args.render)
    checks.output_file("save", args.save)
    if args.render and not args.render.lower().endswith(".png"):
        raise UserError(f"--render must name a .png file, got {args.render}")
    if args.save and not args.save.lower().endswith(".blend"):
        raise UserError(f"--save must name a .blend file, got {args.save}")
    if not 0 <= args.view < 36:
        raise UserError(f"--view must be 0..35, got {args.view}")
    if args.size < 8:
        raise UserError(f"--size must be at least 8, got {args.size}")

    from addon.core.splats import splat_import
    from addon.core.splats.splat_import import RADIUS_SCALE

    paths = splat_import.expand_inputs(args.ply)
    if args.frame is not None and not 1 <= args.frame <= len(paths):
        raise UserError(f"--frame must be 1..{len(paths)}, got {args.frame}")
    rs = RADIUS_SCALE if args.radius_scale is None else args.radius_scale
    if not rs > 0 or rs == float("inf"):
        raise UserError(f"--radius-scale must be a positive number, got {args.radius_scale}")
    if args.mode != "preview" and (args.shading != "emission" or args.radius_scale is not None):
        raise UserError("--shading and --radius-scale go with --mode preview")
    if not 0 < args.eps2d < 1e3:  # also refuses NaN
        raise UserError(f"--eps2d must be a positive number of px^2, got {args.eps2d}")
    if args.antialiased and args.mode == "preview":
        raise UserError("--antialiased goes with --mode gaussian or camera")
    if args.mode == "camera" and not args.render and not args.save:
        raise UserError("--mode camera builds the Gaussians for one camera: give --render or --save")

    import bpy

    from addon.core.scene import reset_scene

    camera = render_camera(args, paths) if args.render or args.save else None
    scene = reset_scene()  # the binary's startup file would add a cube, a lamp and a camera
    objs = splat_import.import_splats(paths, shading=args.shading, radius_scale=rs, mode=args.mode,
                                      sh_degree=args.sh_degree, camera=camera, eps2d=args.eps2d,
                                      antialiased=args.antialiased)
    print(f"import_splats: {len(paths)} file(s), {sum(len(o.data.vertices) for o in objs)} points")
    if camera is not None:
        setup_render(scene, camera, args)
    if args.save:
        from cyclist_formats.atomic import atomic_path

        with atomic_path(args.save) as tmp:
            os.remove(tmp)  # an existing file would make Blender keep a .blend1 backup of it
            bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(tmp), copy=True)
        print(f"import_splats: saved {args.save}")
    if args.render:
        render(scene, paths, args)
    return 0


def render_camera(args, paths):
    """(K, R, T, width, height) of the render: --camera, or ring view --view around the centre of
    the Gaussians' bounding box at --size with the ring's field of view."""
    from addon.core.render.render_pose import load_camera
    from addon.core.splats.splat_import import data_bbox
    from cyclist_formats import ring

    if args.camera:
        K, R, T = load_camera(args.camera, ".")
        size = int(round(2 * K[0, 2]))
        return K, R, T, size, size
    lo, hi = data_bbox(paths)
    focal = ring.FOCAL * args.size / ring.SIZE  # a smaller image keeps the ring's field of view
    R, T, _ = ring.view(args.view, (lo + hi) / 2)
    return ring.intrinsics(args.size, focal), R, T, args.size, args.size


def setup_render(scene, camera, args):
    from dataclasses import replace

    from addon.core.render import render
    from addon.core.splats import splat_billboard, splat_gaussian

    K, R, T, size, _ = camera
    s = replace(render.RenderSettings(), size=size)
    if args.samples:
        s = replace(s, samples=args.samples)
    elif args.mode != "preview":
        s = replace(s, samples=1)  # deterministic: every sample is the same pixel-centre ray
    if args.denoise:
        s = replace(s, denoise=args.denoise)
    elif args.mode != "preview":
        s = replace(s, denoise="NONE")
    try:
        render.configure_cycles(scene, s)
    except TypeError:  # Debian's Blender 3.4 is built without OpenImageDenoise
        print("import_splats: no OpenImageDenoise in this Blender, rendering without denoising")
        render.configure_cycles(scene, replace(s, denoise="NONE"))
    cy = scene.cycles
    if args.mode == "preview":
        # Each translucent sphere costs one transparent bounce (back faces are skipped in the
        # material); configure_cycles' 2 would turn a stack of splats opaque black.
        cy.transparent_max_bounces = 64
    else:  # gaussian and camera: the pixel-centre ray, through every square (no Russian roulette)
        cy.pixel_filter_type, cy.filter_width = splat_billboard.POINT_FILTER
        cy.transparent_max_bounces = cy.min_transparent_bounces = splat_billboard.TRANSPARENT_BOUNCES
    if args.mode != "preview":
        # the Gaussians emit display values: Raw writes the composite as it is (splat_gaussian)
        scene.view_settings.view_transform = splat_gaussian.DISPLAY_VIEW_TRANSFORM
    render.setup_lighting(scene)
    cam = render.ensure_camera(scene, size, float(K[0, 0]))
    render.place_camera(cam, R, T)
    for obj in scene.objects:  # Blender 3.x: the Gaussian squares face this camera
        splat_gaussian.set_camera(obj, cam)


def render(scene, paths, args):
    from addon.core.render import render as R

    if len(paths) == 1:
        jobs = [(scene.frame_current, args.render)]
    elif args.frame is not None:
        jobs = [(args.frame, args.render)]
    else:
        jobs = [(f, frame_path(args.render, f)) for f in range(1, len(paths) + 1)]
    for i, (frame, out) in enumerate(jobs):
        scene.frame_set(frame)
        R.render_atomic(scene, out, derive=False)
        print(f"import_splats: rendered frame {frame} ({i + 1}/{len(jobs)}) -> {out}", flush=True)


if __name__ == "__main__":
    run_main(main, "import_splats.py")

"""`python -m splatting library build [--bikes ID ...] [--riders ID ...] [--engine local|ray]`.

For every bike under OUT/bikes (or the ones named): its 36-view renders (frame, steering, crank,
whole) -> its part Gaussians trained at rest -> the parts fine-tuned together through the 8-DoF
pose on posed Blender renders (bike-posed-train, the asset recipe's second step; off with
--no-posed-train) -> a ground-truth check (the composed Gaussian bike against Blender at fixed
random poses: mask IoU, box PSNR).  For every rider named (`--riders all`: the roster): its
avatar.  Finished tasks are skipped (OUT/library/tasks/), so a killed build rerun finishes with
the same files; OUT/library.json lists every asset with its files and hashes, quality numbers,
build time, settings, and whether it clears the quality floor (datasets use only those).
The bikes themselves come from `make bikes` (blender_scripts/make_bikes.py).
"""
import os
import time

from cyclist_formats import checks
from cyclist_formats.atomic import remove_stale
from cyclist_formats.errors import UserError
from cyclist_formats import bike_folder
from splatting.bike.recipes import LIBRARY, RECIPES, for_bikes  # torch-free: names and option dicts
from splatting.library.ray_address import check_address
from splatting.library import manifest

# The stage's modules are imported inside the functions below, not at the top: they load torch
# (~2.5 s, python -X importtime), and `--help` and the argument checks answer before that (0.2-0.5 s).
# So is settings.py (pydantic: --help 0.26 -> 0.61 s, median of 9 on the loaded 2-core machine).


def add_arguments(p):
    p.add_argument("--out", default="out", help="library root holding bikes/ (default out); library.json goes here")
    p.add_argument("--bikes", nargs="*", default=None, help="bike ids under OUT/bikes (default: all of them)")
    p.add_argument("--riders", nargs="*", default=None,
                   help="roster rider ids whose avatars to build, or 'all' (default: none)")
    p.add_argument("--riders-root", default=os.path.join("data", "riders"), help="avatars go to RIDERS_ROOT/ID/")
    p.add_argument("--engine", choices=("local", "ray"), default="local",
                   help="local: a pool of --workers on this machine (default); ray: a Ray task graph")
    p.add_argument("--address", help="with --engine ray: 'auto' or HOST:PORT of a running cluster (default: a local one)")
    p.add_argument("--workers", type=int, default=1, help="local engine: tasks at a time (default 1)")
    p.add_argument("--retries", type=int, default=1, help="retries of a failed task (default 1)")
    b = p.add_argument_group("budget (recorded in library.json; a library keeps one budget)")
    b.add_argument("--size", type=int, default=None,
                   help="view size in pixels (default: the recipe's, 256 for real, else 512)")
    b.add_argument("--samples", type=int, default=None,
                   help="Cycles samples (default: the recipe's, 128 for real, else the renderer's)")
    b.add_argument("--iterations", type=int, default=None,
                   help="training iterations per part (default: the recipe's, else 3000)")
    b.add_argument("--time-budget-s", type=float, default=600.0, help="training wall-time cap per part (default 600)")
    b.add_argument("--max-gaussians", type=int, default=None,
                   help="per part / avatar (default: the recipe's, else 15000)")
    b.add_argument("--rider-iterations", type=int, default=1500, help="avatar training iterations (default 1500)")
    b.add_argument("--gt-poses", type=int, default=3, help="ground-truth poses per bike (default 3)")
    b.add_argument("--recipe", choices=tuple(RECIPES), default=None,
                   help="asset recipe (splatting/bike/recipes.py): fidelity = parts trained antialiased and issue "
                        "14's long fine-tune (32 dB at random poses; 3.1x the fine-tune's CPU, 1.9x the Gaussians); "
                        "real = downloaded bikes' (docs/curation.md); "
                        "--posed-* options still override it (default: real when every bike built was curated "
                        "from a downloaded model, meta.json generator 'curated'; default for procedural bikes)")
    f = p.add_argument_group("posed fine-tune (python -m splatting bike-posed-train; recorded like the budget)")
    f.add_argument("--no-posed-train", action="store_true",
                   help="skip the fine-tune: train tasks write gaussians/<part>.ply, no posed:<bike> task "
                        "(quick builds; the city bike at random poses: 28.5 dB / IoU 0.962 without, 31.1 / 0.975 with it, "
                        "docs/training.md)")
    f.add_argument("--posed-poses", type=int, default=None,
                   help="posed whole-bike renders per bike (default: bike-posed-train's, see its --help)")
    f.add_argument("--posed-iterations", type=int, default=None, help="fine-tune steps (default: bike-posed-train's)")
    f.add_argument("--posed-samples", type=int, default=None,
                   help="Cycles samples of the posed renders (default: --samples when given, else bike-posed-train's)")
    f.add_argument("--posed-sh-degree", type=int, choices=(0, 1, 2), default=None,
                   help="SH degree of the fine-tuned parts (default: bike-posed-train's)")
    q = p.add_argument_group("quality floor (assets below it are marked unusable)")
    q.add_argument("--min-part-psnr", type=float, default=manifest.FLOORS["min_part_psnr"])
    q.add_argument("--min-iou", type=float, default=manifest.FLOORS["min_gt_iou"])
    q.add_argument("--min-box-psnr", type=float, default=manifest.FLOORS["min_gt_box_psnr"])
    q.add_argument("--min-rider-psnr", type=float, default=manifest.FLOORS["min_rider_psnr"])
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def check_args(args):
    checks.output_dir("out", args.out)
    budget_of(args)  # the budget and the floor against their models (settings.py): one line naming the field
    floors_of(args)
    checks.integer("posed_poses", args.posed_poses, 5, 10_000)  # 4 are held out
    checks.count("posed_iterations", args.posed_iterations, hi=10_000_000)
    checks.count("posed_samples", args.posed_samples, hi=1 << 16)
    if args.no_posed_train and any(v is not None for v in (args.posed_poses, args.posed_iterations,
                                                            args.posed_samples, args.posed_sh_degree)):
        raise UserError("--posed-* settings go with the posed fine-tune, not with --no-posed-train")
    checks.integer("workers", args.workers, 1, 1024)
    checks.integer("retries", args.retries, 0, 100)
    checks.output_dir("riders_root", args.riders_root)
    if args.address and args.engine != "ray":
        raise UserError("--address goes with --engine ray")
    check_address(args.address)


def _bike_ids(root):
    """The bike folders under root (those holding a bike.blend), sorted."""
    return sorted(b for b in os.listdir(root) if os.path.isfile(os.path.join(root, b, "bike.blend"))) \
        if os.path.isdir(root) else []


def recipe_of(args):
    """--recipe, else the one for the bikes this build takes (recipes.for_bikes over their meta.json:
    curated -> real, procedural -> default; the bikes as select() finds them, unknown ids left to it)."""
    if args.recipe is not None:
        return args.recipe
    root = os.path.join(args.out, "bikes")
    have = _bike_ids(root)
    ids = have if args.bikes is None else [b for b in args.bikes if b in have]
    return for_bikes([bike_folder.read_meta(os.path.join(root, b)) for b in ids])


def select(args):
    """({bike id: folder}, [rider ids]) named by the arguments, every one checked to exist."""
    root = os.path.join(args.out, "bikes")
    have = _bike_ids(root)
    if args.bikes is None:
        bikes = have
    else:
        bad = [b for b in args.bikes if b not in have]
        if bad:
            raise UserError(f"no bike {bad[0]!r} under {root} (has {', '.join(have[:5]) or 'none'}"
                            f"{', ...' if len(have) > 5 else ''}); generate bikes with `make bikes OUT={args.out}`")
        bikes = list(args.bikes)
    riders = []
    if args.riders:
        from splatting.rider.roster import all_riders
        known = [r["id"] for r in all_riders()]
        riders = known if args.riders == ["all"] else list(args.riders)
        bad = [r for r in riders if r not in known]
        if bad:
            raise UserError(f"unknown rider {bad[0]!r} (see `python -m splatting rider --list`)")
    if not bikes and not riders:
        raise UserError(f"nothing to build: no bikes under {root} (generate them with `make bikes OUT={args.out}`) "
                        f"and no --riders")
    return {b: os.path.join(root, b) for b in bikes}, riders


def budget_of(args, recipe=None):
    """The Budget of the flags (checked field by field; torch-free, so check_args runs it first);
    recipe: recipe_of(args) when the caller has it already (it reads every bike's meta.json)."""
    from splatting.library.settings import budget
    recipe = recipe or recipe_of(args)
    train, lib = RECIPES[recipe]["train"], LIBRARY.get(recipe, {})  # the recipe's budget unless given
    return budget(view_size=lib.get("view_size", 512) if args.size is None else args.size,
                  samples=lib.get("samples") if args.samples is None else args.samples,
                  iterations=args.iterations or train.get("iterations", 3000),
                  time_budget_s=args.time_budget_s,
                  max_gaussians=args.max_gaussians or train.get("densify", {}).get("max_gaussians", 15000),
                  rider_iterations=args.rider_iterations, gt_poses=args.gt_poses, gt_seed=0,
                  riders_root=os.path.abspath(args.riders_root), posed_train=not args.no_posed_train,
                  antialiased=bool(train.get("antialiased")))


def settings_of(args):
    """LibrarySettings of the flags: the budget and, with the posed stage on, its fine-tune."""
    from splatting.library.settings import LibrarySettings
    recipe = recipe_of(args)
    return LibrarySettings(budget_of(args, recipe), posed_settings(args, recipe) if not args.no_posed_train else None)


def posed_settings(args, recipe=None):
    """The fine-tune's whole configuration (a PosedTrainConfig): the options given here plus every
    other PosedTrainConfig default (rates, rest fraction, denoiser, ...), so that a default changed
    in splatting/bike/posed_config.py is a settings change too (it is recorded as posed_<field>),
    never a silent one.  Resolved here, not in add_arguments: the module imports torch, --help should not."""
    from splatting.bike.recipes import posed_config
    recipe = recipe or recipe_of(args)
    d = posed_config(recipe)
    return d.model_copy(update=dict(
        poses=args.posed_poses or d.poses, iterations=args.posed_iterations or d.iterations,
        samples=args.posed_samples or args.samples or LIBRARY.get(recipe, {}).get("samples") or d.samples,
        sh_degree=d.sh_degree if args.posed_sh_degree is None else args.posed_sh_degree))


def floors_of(args):
    from splatting.library.settings import floors
    return floors(min_part_psnr=args.min_part_psnr, min_gt_iou=args.min_iou, min_gt_box_psnr=args.min_box_psnr,
                  min_rider_psnr=args.min_rider_psnr)


def build(args):
    """Run (or finish) the build; returns (library.json doc, {task: skipped}, wall seconds)."""
    from splatting.library import engine
    from splatting.library.tasks import make_graph

    bikes, riders = select(args)
    root = args.out
    settings = settings_of(args)
    graph = make_graph(root, bikes, riders, posed=settings.budget.posed_train)
    from splatting.library.tasks import task_settings
    manifest.check_all_settings(root, [(t.id, task_settings(t.kind, settings)) for t in graph])  # before any task runs
    for d in bikes.values():  # a killed run's half-written temporaries; their tasks are not recorded
        remove_stale(d)
    t0 = time.time()
    if args.engine == "ray":
        state = engine.run_ray(graph, root, settings, args.address, args.retries, args.quiet)
    else:
        state = engine.run_local(graph, root, settings, args.workers, args.retries, args.quiet)
    wall = time.time() - t0
    doc = manifest.build_manifest(root, graph, floors_of(args), settings, args.engine)
    return doc, state, wall


def run(args):
    doc, state, wall = build(args)
    n_skip = sum(state.values())
    assets = list(doc["bikes"].values()) + list(doc["riders"].values())
    bad = [a["id"] for a in assets if not a["usable"]]
    print(f"library: {len(state)} tasks ({len(state) - n_skip} run, {n_skip} done earlier) in {wall:.1f} s; "
          f"{len(assets) - len(bad)} of {len(assets)} assets usable"
          f"{' (below the floor: ' + ', '.join(bad) + ')' if bad else ''}; manifest {os.path.join(args.out, manifest.MANIFEST)}")
    return 0

"""The asset recipes: which options make a bike's part Gaussians (docs/training.md).

default   `python -m splatting train` per part, then `bike-posed-train`: what `library build` uses for
          procedural bikes and the demo-sized budgets (31.07 dB / IoU 0.9755 against the 512-sample references at
          the 12 blender_compare poses).
fidelity  issue 14's recipe, the one that reaches its 32 dB: parts trained with the mip filter,
          then a densified, longer fine-tune with degree-2 SH and Cycles' pixel filter (32.02 dB /
          0.9842, rounds 4-5). Its price: 3.1x the default fine-tune's CPU (1 631 s against 528 s
          on this machine) and 1.9x the Gaussians to store and render (83 787 against 44 881).

real      downloaded bikes (docs/curation.md, "Real models against Blender"): antialiased parts,
          1 000 steps, then a densified fine-tune (96 poses, 6 000 steps with the rates decayed to 3 %
          over the last 2 000, degree-2 SH, <= 60 000 Gaussians a part, eps2d 0.173), at 256 px views
          and 128 spp (LIBRARY).  `library build`'s default for bikes curated from
          downloaded models (meta.json generator "curated", for_bikes); what bench/real_bikes.py measures.

Each recipe is {"train": TrainConfig fields, "posed": PosedTrainConfig fields}; the command lines
are `train --antialiased` and `bike-posed-train --densify --densify-max 30000 --iterations 10000
--lr-decay 0.03 --lr-tail 2000 --sh-degree 2 --eps2d 0.173`. `make bench` builds its bike with
`fidelity`, so that bike_fidelity measures the recipe that claims the goal.
"""
from cyclist_formats.errors import UserError

RECIPE_FIELD = "recipe field"
DEFAULT = {"train": {}, "posed": {}}

FIDELITY = {
    "train": {"antialiased": True},
    "posed": {"densify": True, "densify_max": 30000, "iterations": 10000, "lr_decay": 0.03, "lr_tail": 2000,
              "sh_degree": 2, "eps2d": 0.173},  # 0.173 px^2: Cycles' 1.5 px Blackman-Harris pixel filter
}

# downloaded bikes (docs/curation.md, "Real bikes against Blender"): what bench/real_bikes.py builds them with
# (docs/curation.md): parts trained antialiased for 1000 steps (3000 changed the frame by +0.08 dB,
# IoU +0.0000), then a short densified fine-tune on 48 posed renders with Cycles' pixel filter: on
# the spoked city bike 31.87 dB / IoU 0.952 against 30.81 / 0.928 for the plain parts' fine-tune.
# The fine-tune's budget (docs/curation.md, "Levers on the motor vehicles"): 48 poses / 1 500 steps /
# SH 1 / <= 30 000 Gaussians left the Harley and the motor scooter at 29.2 dB; 3 000 steps with the
# rates' decay and <= 60 000 Gaussians gained +0.36 / +0.53 dB, 96 poses and SH 2 another +0.22 (Harley);
# 6 000 steps (decay over the last 2 000) took them to 30.21 / 31.05 dB, IoU 0.9940 / 0.9956
REAL = {"train": {"antialiased": True, "iterations": 1000, "densify": {"max_gaussians": 15000}},
        "posed": {"poses": 96, "iterations": 6000, "densify": True, "densify_max": 60000, "lr_decay": 0.03,
                  "lr_tail": 2000, "sh_degree": 2, "eps2d": 0.173}}

RECIPES = {"default": DEFAULT, "fidelity": FIDELITY, "real": REAL}

# the library budget a recipe was measured at, used where `library build` is not given --size /
# --samples (the default recipe: none, so procedural bikes keep the library's 512 px, renderer's samples)
LIBRARY = {"real": {"view_size": 256, "samples": 128}}


def for_bikes(metas):
    """The recipe `library build` uses when none is named, from the meta.json of every bike it
    builds: `real` when all were curated from downloaded models (generator "curated", what
    curate.py writes), `default` when none was (procedural bikes, generator "procedural", and a
    build of riders only).  A library keeps one budget, so a mix is refused: name --recipe."""
    curated = [m.get("generator") == "curated" for m in metas]
    if curated and all(curated):
        return "real"
    if not any(curated):
        return "default"
    raise UserError(f"the bikes mix {sum(curated)} curated and {len(curated) - sum(curated)} other ones, whose "
                    f"default recipes differ (real, default); a library keeps one budget: name --recipe or build "
                    f"them into two libraries")


# the configs' modules load torch (~2.5 s, python -X importtime) and pydantic; imported where a config is
# made, so `library build`'s argument checks, which read RECIPES, stay torch- and pydantic-free
def train_config(recipe, **runtime):
    """TrainConfig of a recipe (name or dict) plus runtime fields (threads, time_budget_s, ...); a bad
    or unknown field is one UserError naming it."""
    from cyclist_formats.typed_config import validate
    from splatting.training.config import TrainConfig

    return validate(TrainConfig, {**_get(recipe)["train"], **runtime}, RECIPE_FIELD)


def posed_config(recipe, **runtime):
    """PosedTrainConfig of a recipe (name or dict) plus runtime fields (progress, ...); a bad or unknown
    field is one UserError naming it."""
    from cyclist_formats.typed_config import validate
    from splatting.bike.posed_config import PosedTrainConfig

    return validate(PosedTrainConfig, {**_get(recipe)["posed"], **runtime}, RECIPE_FIELD)


def _get(recipe):
    if isinstance(recipe, dict):
        return recipe
    if recipe not in RECIPES:
        raise ValueError(f"unknown recipe {recipe!r} (known: {', '.join(RECIPES)})")
    return RECIPES[recipe]

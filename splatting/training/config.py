"""The training configs as typed_config models (pydantic blocks: unknown fields refused, frozen,
ranges in the field declarations): TrainConfig with its nested DensifyConfig (the trainer's and its
densification strategy's), and FineTuneRates, the posed fine-tunes' rates (bike/posed_config.py,
rider/posed_train.py).  A field with a description is its command's option (training/command.py,
rider-avatar), built by typed_config.add_model_arguments; a record of one is typed_config.record_of.

Kept apart from the trainer so that the commands' --help builds its options without importing the
training code (strategy.py's rotations import roma, which loads torch._dynamo: ~2 s of `train --help`).
"""
from typing import Annotated, Optional

from cyclist_formats.checks import MAX_COUNT, MAX_GAUSSIANS, MAX_THREADS
from cyclist_formats.typed_config import Block, Bool, Choice, Field, Int, Number
from splatting.raster.constants import EPS2D

DEFAULT_HOLDOUT = (3, 12, 21, 30)
STRATEGY_NAMES = ("default", "fixed")  # strategy.STRATEGIES: the classes behind the names
Rate = Annotated[Number, Field(ge=0)]  # an Adam learning rate (0: the group stays where it is)


class DensifyConfig(Block):
    """The adaptive density control's rules (DensifyStrategy); a field with a description is a
    `train` option (training/command.py)."""
    grad_threshold: Annotated[Number, Field(gt=0)] = 0.0002  # mean view-space gradient norm (NDC units, INRIA)
    percent_dense: Annotated[Number, Field(gt=0, le=1)] = 0.01  # x extent: max scale below -> clone, above -> split
    split_n: Annotated[Int, Field(ge=1)] = 2
    start: Annotated[Int, Field(ge=0)] = 200  # iterations
    stop: Annotated[Int, Field(ge=0)] = 2500
    every: Annotated[Int, Field(ge=1)] = 100
    reset_every: Annotated[Int, Field(ge=0)] = 0  # opacity reset period (0 = never); INRIA 3000 of 30000
    min_opacity: Annotated[Number, Field(ge=0, le=1)] = 0.005  # prune below
    # prune Gaussians wider than this fraction of the image (after a reset) ...
    max_screen_frac: Annotated[Number, Field(gt=0)] = 0.15
    max_world_frac: Annotated[Number, Field(gt=0)] = 0.1  # ... or larger than this fraction of the extent
    # hard budget: 40k gained 0.25 dB (box) on a frame for 1.7x the time (docs/training.md)
    max_gaussians: Annotated[Int, Field(ge=1, le=MAX_GAUSSIANS, description="hard budget of Gaussians")] = 15000
    hull_prune: Bool = True  # drop Gaussians whose centre leaves the dilated silhouettes


class TrainConfig(Block):
    """A part's training; a field with a description is a `train` option (training/command.py
    derives them, nested blocks' too), so every default is written here only.  Its record, PART.json's
    "config", is typed_config.record_of's."""
    iterations: Annotated[Int, Field(ge=1, le=MAX_COUNT, description="optimisation steps at most")] = 3000
    time_budget_s: Annotated[Number, Field(gt=0, description="stop after this much wall time")] = 600.0
    sh_degree: Choice(0, 1, 2, 3) = Field(0, description="spherical-harmonics degree")
    holdout: tuple[Annotated[Int, Field(ge=0)], ...] = Field(DEFAULT_HOLDOUT, description="held-out view indices (comma list)")
    seed: Annotated[Int, Field(ge=0, description="random seed")] = 0
    # mip-splatting's 2D filter with opacity compensation (raster/sparse.py); a model trained with it
    # must be rendered with it (its PART.json config says so)
    antialiased: Bool = Field(False, description="antialiased splatting in training and evaluation")
    # the splats' screen-space low-pass (px^2, rasterize's eps2d); the part is drawn with it ever
    # after (PART.json config; absent: 0.3). Cycles' 1.5 px Blackman-Harris pixel filter: 0.173
    eps2d: Annotated[Number, Field(gt=0, le=10, description="screen-space low-pass variance (px^2) added to every "
                                                            "splat in training, kept with the part for every render")] = EPS2D
    # 1 by default: on the shared 2-core machine 2 threads ran 4-7x slower per iteration
    # (oversubscription), see docs/training.md; None leaves torch's default
    threads: Optional[Annotated[Int, Field(ge=1, le=MAX_THREADS)]] = Field(
        1, description="torch.set_num_threads (1: measured fastest on 2 shared cores)")
    # coarse-to-fine: (first iteration, image scale); renders are always cropped to the object
    resolution_schedule: Annotated[tuple[tuple[Annotated[Int, Field(ge=0)], Annotated[Number, Field(gt=0, le=1)]], ...],
                                   Field(min_length=1)] = ((0, 1.0),)
    crop_margin_px: Annotated[Int, Field(ge=0)] = 8  # at full resolution
    # INRIA learning rates; the means' rate is x extent (object bounding-box diagonal, metres)
    lr_means: Annotated[Number, Field(gt=0)] = 1.6e-4
    lr_means_final: Annotated[Number, Field(gt=0)] = 1.6e-6
    lr_sh0: Rate = 2.5e-3
    lr_shN: Rate = 2.5e-3 / 20
    lr_opacity: Rate = 0.05
    lr_scales: Rate = 5e-3
    lr_quats: Rate = 1e-3
    lambda_dssim: Annotated[Number, Field(ge=0, le=1)] = 0.2
    init_max_points: Annotated[Int, Field(ge=1)] = 10000  # subsample points.ply beyond this
    init_opacity: Annotated[Number, Field(gt=0, lt=1)] = 0.1
    eval_every: Annotated[Int, Field(ge=1)] = 200
    patience: Annotated[Int, Field(ge=0)] = 3  # evaluations without a min_delta gain before stopping
    min_delta_db: Annotated[Number, Field(ge=0)] = 0.05
    progress: Bool = True
    strategy: Choice(*STRATEGY_NAMES) = Field("default", description="densification strategy")
    densify: DensifyConfig = Field(default_factory=DensifyConfig)


class FineTuneRates(Block):
    """Adam rates and loss weight for fine-tuning Gaussians a full training already placed (the posed
    fine-tunes of riders and bikes): the means' rate (x extent) a tenth of the trainer's start."""
    lr_means: Annotated[Number, Field(gt=0)] = 1.6e-5
    lr_sh0: Rate = 2.5e-3
    lr_opacity: Rate = 0.02
    lr_scales: Rate = 2.5e-3
    lr_quats: Rate = 1e-3
    lambda_dssim: Annotated[Number, Field(ge=0, le=1)] = 0.2

    def rates(self, extent):
        """Adam learning rates per parameter group (the means' scaled by the object's extent)."""
        return {"means": self.lr_means * extent, "quats": self.lr_quats, "log_scales": self.lr_scales,
                "opacity_logits": self.lr_opacity, "sh0": self.lr_sh0}

"""bike-posed-train's config as a typed_config model (splatting/bike/posed_train.py runs it): every
field with a description is a `bike-posed-train` option (bike/command.py), every default written
here only; the library's posed stage records it field by field (posed_<field>).  Apart from the
fine-tune so that `bike-posed-train --help` builds its options without the training code."""
from typing import Annotated, ClassVar

from pydantic import field_validator
from pydantic_core import PydanticCustomError

from cyclist_formats.typed_config import Bool, Choice, Field, Int, Number, Str
from splatting.raster.constants import EPS2D
from splatting.training.config import FineTuneRates, Rate

HELD_OUT = 4  # the last posed views: scored before and after, never trained on


class PosedTrainConfig(FineTuneRates):  # + the fine-tune's learning rates (training/config.py)
    """The posed fine-tune; a field with a description is a `bike-posed-train` option (bike/command.py
    derives them), every default written here only.  Its record (posed_train.json's "config", the
    library's posed_<field> settings) is typed_config.record_of's: every field but progress."""
    # defaults measured in docs/training.md (whole bike at the 12 blender_compare poses): 48 -> 144
    # poses +0.39 dB, degree-1 SH +0.24, 1000 -> 3000 iterations +0.18, 3000 -> 6000 +0.25.
    RECORD_EXCLUDE: ClassVar[tuple] = ("progress",)
    poses: Annotated[Int, Field(ge=HELD_OUT + 1, le=10_000,
                                description="posed whole-bike renders (one random ring camera each)")] = 144
    iterations: Annotated[Int, Field(ge=1, le=10_000_000, description="fine-tuning steps")] = 6000
    rest_fraction: Annotated[Number, Field(ge=0, le=1)] = 0.25  # share of steps on the rest-pose whole-bike ring (views/whole)
    samples: Annotated[Int, Field(ge=1, le=1 << 16, description="Cycles samples of the posed renders")] = 128
    denoise: Str = "FAST"
    seed: Annotated[Int, Field(ge=0)] = 0
    crop_margin_px: Annotated[Int, Field(ge=0)] = 8
    # 1 (2): the fine-tune adds degree-1 (and 2) SH (view-dependent colour), rotated with each part
    sh_degree: Choice(0, 1, 2) = Field(1, description="1 or 2: add view-dependent (degree-1 or 2 SH) colour in "
                                                      "the fine-tune")
    lr_shN: Rate = 2.5e-3       # the band-1 coefficients' rate (the DC's; INRIA's /20 gained less)
    # adaptive density control per part in the first half (docs/training.md)
    densify: Bool = Field(False, description="grow each part's Gaussians (adaptive density control) "
                                             "in the first half of the fine-tune")
    densify_max: Annotated[Int, Field(ge=1, le=10_000_000, description="with --densify: most Gaussians per part")] = 30000
    lr_decay: Annotated[Number, Field(gt=0, le=1, description="every learning rate decays exponentially to this "
                                                              "fraction of its start by the last step (1: constant)")] = 1.0
    lr_tail: Annotated[Int, Field(ge=0, description="with --lr-decay: constant rates, then the decay over the "
                                                    "last N steps only (0: over the whole fine-tune)")] = 0
    # the bike keeps it (posed_train.json) and every renderer draws its parts with it
    eps2d: Annotated[Number, Field(gt=0, le=10, description="screen-space low-pass variance in px^2 added to every "
                                                            "splat in the fine-tune and kept with the bike for every "
                                                            "later render (Cycles' 1.5 px Blackman-Harris pixel "
                                                            "filter has variance 0.173)")] = EPS2D
    progress: Bool = True

    @field_validator("lr_tail")
    @classmethod
    def _tail_within_the_run(cls, v, info):
        n = info.data.get("iterations")
        if n is not None and v > n:
            raise PydanticCustomError("tail", "expected a value <= iterations ({n})", {"n": n})
        return v

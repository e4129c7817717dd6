"""The library build's settings as typed objects: the budget and the quality floor as pydantic models
(one per block, extra="forbid", ranges in the field declarations, errors as one line naming the
field), the posed fine-tune as the training stage's own PosedTrainConfig (its fields and defaults
are written once, in splatting/bike/posed_config.py).

The tasks read attributes (`s.budget.view_size`, `s.posed.iterations`); the records on disk (each
task's settings in OUT/library/tasks/*.json and library.json's "settings" and "quality_floor") are
`LibrarySettings.record()` and `Floors.record()`: the flat dicts the library has always written, key
for key and value for value, so libraries built earlier still match and resume.

Torch-free on purpose: `library build` checks its budget and floor flags against these models
before anything loads (the posed block comes later, from the recipe).  The command imports this
module inside its functions: pydantic costs its --help 0.26 -> 0.61 s (median of 9, loaded 2-core
machine), and the floor's defaults it shows are manifest.FLOORS.
"""
from dataclasses import dataclass
from typing import Annotated, Any, Optional

from cyclist_formats.checks import MAX_GAUSSIANS, MAX_IMAGE_SIZE
from cyclist_formats.typed_config import Block, Bool, Field, Int, Number, Str, record_of, validate
from splatting.library.manifest import FLOORS

SETTING = "library setting"


class Budget(Block):
    """What every asset is built with (a library keeps one budget)."""
    view_size: Annotated[Int, Field(ge=32, le=MAX_IMAGE_SIZE, description="view size in pixels")]
    samples: Optional[Annotated[Int, Field(ge=1, le=1 << 16, description="Cycles samples (None: the renderer's)")]] = None
    iterations: Annotated[Int, Field(ge=1, le=10_000_000, description="training iterations per part")]
    time_budget_s: Annotated[Number, Field(gt=0, description="training wall-time cap per part")]
    max_gaussians: Annotated[Int, Field(ge=100, le=MAX_GAUSSIANS, description="per part / avatar")]
    rider_iterations: Annotated[Int, Field(ge=1, le=10_000_000, description="avatar training iterations")]
    gt_poses: Annotated[Int, Field(ge=1, le=1000, description="ground-truth poses per bike")]
    gt_seed: Annotated[Int, Field(ge=0)] = 0
    riders_root: Str = Field(description="avatars go to RIDERS_ROOT/ID/ (absolute)")
    posed_train: Bool = Field(True, description="the posed fine-tune between a bike's trainings and its check")
    antialiased: Bool = Field(False, description="parts trained antialiased (the fidelity recipe); recorded only "
                                                 "when true, so libraries built before the key still match")


class Floors(Block):
    """The quality floor: assets below it are marked unusable in library.json."""
    min_part_psnr: Annotated[Number, Field(ge=0, le=200, description="held-out PSNR of every part, dB")] = FLOORS["min_part_psnr"]
    min_gt_iou: Annotated[Number, Field(ge=0, le=1, description="ground-truth mask IoU")] = FLOORS["min_gt_iou"]
    min_gt_box_psnr: Annotated[Number, Field(ge=0, le=200, description="ground-truth box PSNR, dB")] = FLOORS["min_gt_box_psnr"]
    min_rider_psnr: Annotated[Number, Field(ge=0, le=200, description="avatar held-out PSNR, dB")] = FLOORS["min_rider_psnr"]

    def record(self):
        """library.json's "quality_floor"."""
        return self.model_dump()


def budget(**fields):
    """Budget from its fields; the first bad one is a UserError naming it (library setting 'x': ...)."""
    return validate(Budget, fields, SETTING)


def floors(**fields):
    return validate(Floors, fields, "quality floor")


@dataclass(frozen=True)
class LibrarySettings:
    """A build's settings: the budget, and the posed fine-tune's PosedTrainConfig (None: the stage is
    off, budget.posed_train False)."""
    budget: Budget
    posed: Any = None

    def __post_init__(self):
        if not isinstance(self.budget, Budget):
            raise TypeError(f"LibrarySettings.budget takes a Budget, got {type(self.budget).__name__}")
        if self.budget.posed_train != (self.posed is not None):
            raise ValueError("LibrarySettings: a posed configuration goes with budget.posed_train and only with it")

    def posed_record(self):
        """The fine-tune's configuration as bike-posed-train records it ({field: value}, no `progress`)."""
        return record_of(self.posed) if self.posed is not None else {}

    def record(self):
        """The flat settings dict the library writes: the budget's fields in declaration order
        (antialiased only when true), then posed_<field> for every fine-tune field."""
        out = self.budget.model_dump()
        if not out["antialiased"]:  # absent: not (libraries built before the key)
            del out["antialiased"]
        out.update({"posed_" + k: v for k, v in self.posed_record().items()})
        assert "posed_train" not in self.posed_record()  # the stage's on/off switch
        return out

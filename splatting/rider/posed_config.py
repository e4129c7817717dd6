"""rider-posed-train's config as a typed_config model (splatting/rider/posed_train.py runs it): every
field with a description is a `rider-posed-train` option (rider/command.py), every default written
here only.  Apart from the fine-tune so that `rider-posed-train --help` builds its options without
the training code."""
from typing import Annotated, Optional

from cyclist_formats.typed_config import Bool, Field, Int, Number
from splatting.training.config import FineTuneRates


class PosedTrainConfig(FineTuneRates):  # + the fine-tune's learning rates (training/config.py)
    """The avatar's posed fine-tune; a field with a description is a `rider-posed-train` option
    (rider/command.py derives them), every default written here only."""
    poses: Annotated[Int, Field(ge=1, le=36, description="pedalling poses")] = 4
    cameras: Annotated[Int, Field(ge=2, le=36, description="ring cameras per pose (evenly spaced, offset per pose)")] = 8
    iterations: Annotated[Int, Field(ge=1, le=10 ** 7, description="fine-tuning steps")] = 600
    # 0.5 (256 px) softened the 512 px silhouettes: IoU 0.97 -> 0.93
    scale: Annotated[Number, Field(ge=0.05, le=1, description="training image scale")] = 1.0
    rest_fraction: Annotated[Number, Field(ge=0, le=1)] = 0.25  # share of steps on the rest-pose views
    samples: Optional[Annotated[Int, Field(ge=1, le=1 << 16)]] = Field(
        None, description="Cycles samples for the posed renders (None: the renderer's)")
    seed: Annotated[Int, Field(ge=0)] = 0
    progress: Bool = True

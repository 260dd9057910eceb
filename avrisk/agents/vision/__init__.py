"""The paper's vision ego: PilotNet on the ego camera, throttle from the lidar net.

* :mod:`~avrisk.agents.vision.pilotnet` -- :class:`PilotNet`, the published
  steering network, batch-independent;
* :mod:`~avrisk.agents.vision.ego` -- :class:`PilotNetEgo`, registered as the
  ego policy ``vision_pilotnet``;
* :mod:`~avrisk.agents.vision.store` -- the shipped weights.

Training lives in :mod:`avrisk.learning.vision`.
"""

from avrisk.agents.vision.ego import PilotNetEgo
from avrisk.agents.vision.pilotnet import (
    IMAGE_SHAPE,
    INNER_BATCH,
    PilotNet,
    inner_batch,
)
from avrisk.agents.vision.store import load_pilotnet

__all__ = [
    "IMAGE_SHAPE",
    "INNER_BATCH",
    "PilotNet",
    "PilotNetEgo",
    "inner_batch",
    "load_pilotnet",
]

"""The batched highway simulator. It knows nothing of estimators.

It owns the interfaces that plug into it (:mod:`~avrisk.sim.interfaces`: the
actors that drive vehicles, the safety measure; :mod:`~avrisk.sim.camera`: the
ego's camera) and imports no implementation of them: :mod:`avrisk.agents`,
:mod:`avrisk.safety` and :mod:`avrisk.render` build on this package, and
:mod:`avrisk.assembly` joins them for a scenario. Modules:
:mod:`~avrisk.sim.road`, :mod:`~avrisk.sim.state`, :mod:`~avrisk.sim.geometry`,
:mod:`~avrisk.sim.dynamics`, :mod:`~avrisk.sim.lidar`,
:mod:`~avrisk.sim.collision`, :mod:`~avrisk.sim.observation`,
:mod:`~avrisk.sim.sensing`, :mod:`~avrisk.sim.interfaces`,
:mod:`~avrisk.sim.config`, :mod:`~avrisk.sim.rollout` and
:mod:`~avrisk.sim.simulator`.
"""

from avrisk.sim.camera import Camera, CameraFrame, SemanticClass
from avrisk.sim.collision import Contact
from avrisk.sim.config import SimConfig
from avrisk.sim.interfaces import Action, Actor, NoiseRequest, SafetyMeasure
from avrisk.sim.road import Road
from avrisk.sim.rollout import RolloutResult, Status, Trace
from avrisk.sim.simulator import Simulator
from avrisk.sim.state import VehicleState

__all__ = [
    "Action",
    "Actor",
    "Camera",
    "CameraFrame",
    "Contact",
    "NoiseRequest",
    "RolloutResult",
    "Road",
    "SafetyMeasure",
    "SemanticClass",
    "SimConfig",
    "Simulator",
    "Status",
    "Trace",
    "VehicleState",
]

"""The batched highway simulator. It knows nothing of estimators.

Leaf modules (import them directly): :mod:`~avrisk.sim.road`,
:mod:`~avrisk.sim.state`, :mod:`~avrisk.sim.geometry`,
:mod:`~avrisk.sim.dynamics`, :mod:`~avrisk.sim.lidar`,
:mod:`~avrisk.sim.collision`, :mod:`~avrisk.sim.observation`,
:mod:`~avrisk.tensors.noise`, :mod:`~avrisk.tensors.mathops`. The simulator itself,
:mod:`~avrisk.sim.simulator`, builds on :mod:`avrisk.agents` and
:mod:`avrisk.safety`; its names are loaded on first access so that those
packages can import the leaf modules without a cycle.
"""

from typing import Any

from avrisk.sim.road import Road
from avrisk.sim.state import VehicleState

__all__ = ["RolloutResult", "Road", "SimConfig", "Simulator", "Trace", "VehicleState"]

_LAZY = {"RolloutResult", "SimConfig", "Simulator", "Trace"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        from avrisk.sim import simulator

        return getattr(simulator, name)
    raise AttributeError(f"module 'avrisk.sim' has no attribute {name!r}")

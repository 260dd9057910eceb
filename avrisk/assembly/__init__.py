"""Assembly: a scenario spec built into a simulator, its actors and its measure.

The one layer that joins the scenario data (:mod:`avrisk.scenario`) with the
simulator (:mod:`avrisk.sim`), the drivers and ego policies
(:mod:`avrisk.agents`) and the safety measures (:mod:`avrisk.safety`):

* :mod:`~avrisk.assembly.builder` -- :class:`ScenarioSimulator` (flat ``X``
  and seeds in, rollouts out);
* :mod:`~avrisk.assembly.parts` -- what it is built of: the scenario's ``X``
  layout and ``P0``, the road, the measure, the camera, the actors;
* :mod:`~avrisk.assembly.objective` -- :class:`SimulationObjective`, the
  simulator as the estimation engine's black box;
* :mod:`~avrisk.assembly.traces` -- rollouts as plain arrays, and the traces
  of a run's most likely failures, recorded while it runs;
* :mod:`~avrisk.assembly.trace_camera` -- the ego camera's images of a
  recorded rollout, rendered again from its trace;
* :mod:`~avrisk.assembly.typicality` -- how typical a rollout's start and
  drivers are under ``P0``, as percentiles (the ranking of failures);
* :mod:`~avrisk.assembly.threads` -- torch's CPU threads in this process,
  as many as cores are idle (worker processes: one each, :class:`ObjectiveFactory`).
"""

from avrisk.assembly.builder import ScenarioSimulator
from avrisk.assembly.objective import (
    EVENT_COLUMNS,
    FACT_COLUMNS,
    MECHANISMS,
    ObjectiveFactory,
    SimulationObjective,
)
from avrisk.assembly.parts import (
    base_distribution,
    camera_from_spec,
    initial_state,
    param_layout,
)
from avrisk.assembly.trace_camera import CameraFrames, camera_frames
from avrisk.assembly.traces import (
    FAILURES_FILE,
    FailureRecorder,
    RolloutTrace,
    read_failure_traces,
    resimulate,
    traces_from_rollout,
)
from avrisk.assembly.typicality import Typicality, scenario_typicality

__all__ = [
    "CameraFrames",
    "EVENT_COLUMNS",
    "FACT_COLUMNS",
    "FAILURES_FILE",
    "MECHANISMS",
    "FailureRecorder",
    "ObjectiveFactory",
    "RolloutTrace",
    "ScenarioSimulator",
    "SimulationObjective",
    "Typicality",
    "base_distribution",
    "camera_from_spec",
    "camera_frames",
    "initial_state",
    "param_layout",
    "read_failure_traces",
    "resimulate",
    "scenario_typicality",
    "traces_from_rollout",
]

"""How human-like are the learned drivers? Closed loop against held-out human data.

The report of ``avrisk realism`` (issue 21), on data shipped with the package
and held out before any training (:mod:`~avrisk.realism.held_out`):

* part A (:mod:`~avrisk.realism.car_following`): car following on held-out
  NGSIM I-80 windows, the leader replayed, the follower driven by the learned
  network (``mu0``, ``xi ~ P0``, mean actions) and by IDM; distributions of
  speed, acceleration, jerk, gap, TTC and lateral offset against the humans'
  (:mod:`~avrisk.realism.metrics`), rates of hard braking, collisions and road
  departures, and issue 21's targets (:mod:`~avrisk.realism.targets`);
* part B (:mod:`~avrisk.realism.lane_changes`): lane changes in random
  six-lane traffic against the held-out US-101 vehicles, with IDM+MOBIL;
* :mod:`~avrisk.realism.tables`, :mod:`~avrisk.realism.figures` and
  :mod:`~avrisk.realism.report`: the markdown tables, the PNG figures, and
  the folder they are written to with ``realism.json``.

It drives the simulator (:mod:`avrisk.sim`) with the agents and learning
layers; no estimator.
"""

from avrisk.realism.report import (
    FILES,
    DriverFiles,
    RealismResult,
    RealismSettings,
    run_realism,
    write_report,
)

__all__ = [
    "FILES",
    "DriverFiles",
    "RealismResult",
    "RealismSettings",
    "run_realism",
    "write_report",
]

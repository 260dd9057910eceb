"""avrisk: rare-event risk estimation for autonomous-vehicle policies.

The package is split the way the data flows (``docs/design.md`` gives the
layers, what each may import and why):

* :mod:`avrisk.rare` -- the estimation engine. It knows nothing of cars: it
  sees a base distribution and a batched black-box function ``f``.
* :mod:`avrisk.sim` -- the batched highway simulator. It owns the interfaces
  that plug into it (actors, the safety measure) and knows nothing of
  estimators; :mod:`avrisk.tensors` holds the tensor helpers it shares.
* :mod:`avrisk.agents`, :mod:`avrisk.safety` -- the actors (drivers, ego
  policies) and the safety measures (minimum time-to-collision).
* :mod:`avrisk.scenario` -- the scenario spec and its base distribution ``P0``,
  as data.
* :mod:`avrisk.assembly` -- a scenario built into a simulator, its actors and
  its measure: the estimator's black box.
* :mod:`avrisk.api` -- the scenario-level calls (:func:`estimate`,
  :func:`compare_methods`, :func:`compare_egos`, :func:`simulate`,
  :func:`write_report`), light to import: each loads the simulator when called.
* :mod:`avrisk.cli` -- the ``avrisk`` command, a shell over :mod:`avrisk.api`.
"""

from avrisk.api import (
    compare_egos,
    compare_methods,
    estimate,
    simulate,
    write_report,
)
from avrisk.version import __version__ as __version__

__all__ = ["compare_egos", "compare_methods", "estimate", "simulate", "write_report"]

"""avrisk: rare-event risk estimation for autonomous-vehicle policies.

The package is split the way the data flows (see ``DESIGN.md``):

* :mod:`avrisk.rare` -- the estimation engine. It knows nothing of cars: it
  sees a base distribution and a batched black-box function ``f``.
* :mod:`avrisk.sim`, :mod:`avrisk.safety` -- the batched highway simulator and
  the safety measure (minimum time-to-collision). They know nothing of
  estimators.
* :mod:`avrisk.scenario` -- the scenario spec and its base distribution ``P0``.
* :mod:`avrisk.cli` -- the ``avrisk`` command.
"""

__version__ = "0.1.0"

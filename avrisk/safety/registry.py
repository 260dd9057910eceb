"""The registry of safety measures, by the name a scenario gives.

A safety measure implements :class:`avrisk.sim.interfaces.SafetyMeasure` (the
simulator's interface, documented there): it maps a rollout to one number
``f`` per rollout, low meaning dangerous, evaluated online one state at a
time.
"""

from __future__ import annotations

from avrisk.registry import Registry
from avrisk.safety.box_ttc import MinBoxTTC
from avrisk.safety.ttc import MinTTC

__all__ = ["SAFETY_MEASURES", "get_safety_measure", "register_safety_measure"]


#: The safety measures by name (``"min_ttc"``, ``"min_box_ttc"``), built by
#: ``get_safety_measure(name or "package.module:attribute", params, *,
#: allow_import, **context)`` and extended by ``register_safety_measure(name,
#: factory, *, params)`` (:class:`~avrisk.registry.Registry`). A factory is
#: offered ``n_rays`` (ray TTC's ray count), ``device`` and ``dtype`` and
#: receives those its signature names, plus its validated params.
SAFETY_MEASURES = Registry("safety measure")
register_safety_measure = SAFETY_MEASURES.register
get_safety_measure = SAFETY_MEASURES.build

register_safety_measure("min_ttc", MinTTC)
register_safety_measure("min_box_ttc", MinBoxTTC)

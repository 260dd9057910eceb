"""The registry of safety measures, by the name a scenario gives.

A safety measure implements :class:`avrisk.sim.interfaces.SafetyMeasure` (the
simulator's interface, documented there): it maps a rollout to one number
``f`` per rollout, low meaning dangerous, evaluated online one state at a
time.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from avrisk.registry import Registry
from avrisk.safety.box_ttc import MinBoxTTC
from avrisk.safety.ttc import MinTTC
from avrisk.sim.interfaces import SafetyMeasure

__all__ = ["get_safety_measure", "register_safety_measure"]


_MEASURES = Registry("safety measure")


def register_safety_measure(name: str, factory: Callable[..., Any]) -> None:
    """Make ``factory(**kwargs)`` available as ``get_safety_measure(name, ...)``."""
    _MEASURES.register(name, factory)


def get_safety_measure(name: str, **kwargs: Any) -> SafetyMeasure:
    """Build a registered safety measure by name (e.g. ``"min_ttc"``).

    Raises
    ------
    KeyError
        If ``name`` is not registered; the message lists the known names.
    """
    return _MEASURES.build(name, **kwargs)


register_safety_measure("min_ttc", MinTTC)
register_safety_measure("min_box_ttc", MinBoxTTC)

"""The registry of safety measures, by the name a scenario gives.

A safety measure implements :class:`avrisk.sim.interfaces.SafetyMeasure` (the
simulator's interface, documented there): it maps a rollout to one number
``f`` per rollout, low meaning dangerous, evaluated online one state at a
time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from pydantic import BaseModel

from avrisk.registry import Registry
from avrisk.safety.box_ttc import MinBoxTTC
from avrisk.safety.ttc import MinTTC
from avrisk.sim.interfaces import SafetyMeasure

__all__ = ["get_safety_measure", "register_safety_measure"]


_MEASURES = Registry("safety measure")


def register_safety_measure(
    name: str, factory: Callable[..., Any], *, params: type[BaseModel] | None = None
) -> None:
    """Make ``factory`` available as ``get_safety_measure(name, ...)``.

    ``params`` is its params model (default: ``factory.Params``, if any); see
    :meth:`avrisk.registry.Registry.register`.
    """
    _MEASURES.register(name, factory, params=params)


def get_safety_measure(
    name: str,
    params: Mapping[str, Any] | None = None,
    /,
    *,
    allow_import: bool = False,
    **context: Any,
) -> SafetyMeasure:
    """Build a safety measure by registered name or import path.

    Parameters
    ----------
    name : str
        E.g. ``"min_ttc"``, ``"min_box_ttc"``, or ``"mypkg.measures:MyTTC"``.
    params : mapping, optional
        The measure's ``params`` from a scenario, validated by its params model.
    allow_import : bool, default=False
        Whether an import path may be imported.
    **context
        The caller's arguments (``n_rays``, ``device``, ...), passed as they are.

    Raises
    ------
    avrisk.registry.ComponentError
        If ``name`` is unknown (also a ``KeyError``; the message lists the
        known names), cannot be imported, or ``params`` do not validate; see
        :meth:`avrisk.registry.Registry.build`.
    """
    return _MEASURES.build(name, params, allow_import=allow_import, **context)


register_safety_measure("min_ttc", MinTTC)
register_safety_measure("min_box_ttc", MinBoxTTC)

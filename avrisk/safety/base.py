"""The safety-measure interface and its registry.

A safety measure maps a rollout to one number ``f`` per rollout, low meaning
dangerous. It is evaluated online, one state at a time, so the simulator never
keeps a rollout's history:

    carry = measure.init(measure.instant(state_0))
    carry = measure.update(carry, measure.instant(state_t), alive)  # t = 1..T
    f = measure.finalize(carry)

``instant`` maps a state (..., A) to a value (...); ``update`` must leave a
rollout's carry untouched where ``alive`` is false (it stopped).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol, runtime_checkable

from pydantic import BaseModel
from torch import Tensor

from avrisk.registry import Registry
from avrisk.safety.box_ttc import MinBoxTTC
from avrisk.safety.ttc import MinTTC
from avrisk.sim.state import VehicleState

__all__ = ["SafetyMeasure", "get_safety_measure", "register_safety_measure"]


@runtime_checkable
class SafetyMeasure(Protocol):
    """What the simulator needs of a safety measure (see module docstring)."""

    name: str
    #: Primitive geometric tests per (ego, other vehicle) pair and instant; the
    #: simulator sizes its eager batch slices by it (cache-sized temporaries).
    tests_per_pair: int

    def instant(
        self, state: VehicleState, cos: Tensor | None = None, sin: Tensor | None = None
    ) -> Tensor:
        """Value at one instant, shape (B,), for a state of shape (B, A)."""
        ...

    def init(self, value: Tensor) -> Tensor:
        """Carry from the value at ``t = 0``."""
        ...

    def update(self, carry: Tensor, value: Tensor, alive: Tensor) -> Tensor:
        """Fold in one more step's value where ``alive`` (B,)."""
        ...

    def finalize(self, carry: Tensor) -> Tensor:
        """``f`` per rollout, shape (B,)."""
        ...


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

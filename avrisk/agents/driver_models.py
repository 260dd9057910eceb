"""Environment driver models by name, beyond the two a scenario builds in.

A scenario's ``drivers`` entries with ``model: idm_mobil`` or ``model:
learned`` are assembled by :mod:`avrisk.assembly` (their parameters come from
the spec and from ``X``). Any other model is a registered name or an import
path ``package.module:attribute`` to a user's class, built once per scenario
for the vehicles of that driver type: an :class:`~avrisk.sim.interfaces.Actor`
whose ``controlled`` mask is those vehicles. Its factory is offered
``controlled`` (bool (A,)), ``n_vehicles``, ``road``, ``device`` and ``dtype``
and receives those its signature names, plus its validated ``params``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from pydantic import BaseModel

from avrisk.registry import Registry
from avrisk.sim.interfaces import Actor

__all__ = ["get_driver_model", "register_driver_model"]

_DRIVER_MODELS = Registry("driver model")


def register_driver_model(
    name: str, factory: Callable[..., Any], *, params: type[BaseModel] | None = None
) -> None:
    """Make ``factory`` available as ``get_driver_model(name, ...)``."""
    _DRIVER_MODELS.register(name, factory, params=params)


def get_driver_model(
    name: str,
    params: Mapping[str, Any] | None = None,
    /,
    *,
    allow_import: bool = False,
    **context: Any,
) -> Actor:
    """Build a driver model by registered name or import path.

    Raises
    ------
    avrisk.registry.ComponentError
        If ``name`` is unknown, cannot be imported, or ``params`` do not
        validate (see :meth:`avrisk.registry.Registry.build`).
    """
    return _DRIVER_MODELS.build(name, params, allow_import=allow_import, **context)

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

from avrisk.registry import Registry

__all__ = ["DRIVER_MODELS", "get_driver_model", "register_driver_model"]

#: The driver models by name, built by ``get_driver_model(name or
#: "package.module:attribute", params, *, allow_import, **context)`` and
#: extended by ``register_driver_model(name, factory, *, params)``
#: (:class:`~avrisk.registry.Registry`; the context: the module docstring).
DRIVER_MODELS = Registry("driver model")
register_driver_model = DRIVER_MODELS.register
get_driver_model = DRIVER_MODELS.build

"""Ego policies by name, and the constant-command actor.

Every driver and ego policy here is an actor of the simulator
(:class:`avrisk.sim.interfaces.Actor`): it sets the actions of the vehicles it
``controlled``. An ego policy is an actor that controls vehicle 0 only
(:func:`ego_only`); it may use everything in the observation: the ego's own
lidar and lane features (``obs.lidar.range[:, 0]``) as a real vehicle would,
the full state as privileged information. A neural net, a vision net or a
client of an external process all fit.

Ego policies are registered by name (``"constant"``, ``"idm_mobil"``,
``"lidar_imitation"``) for scenario files and the command line
(:func:`get_policy`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import torch
from pydantic import BaseModel, ConfigDict
from torch import Tensor

from avrisk.registry import Registry
from avrisk.sim.interfaces import Action, Actor
from avrisk.sim.observation import Observation

__all__ = ["ConstantPolicy", "ego_only", "get_policy", "register_policy"]


def ego_only(n_vehicles: int, *, device: str | torch.device = "cpu") -> Tensor:
    """The ``controlled`` mask of an ego policy: vehicle 0 of ``n_vehicles``.

    Examples
    --------
    >>> ego_only(3).tolist()
    [True, False, False]
    """
    return torch.arange(n_vehicles, device=device) == 0


class ConstantPolicy:
    """Vehicles that hold fixed commands (cruise control, test double).

    Parameters
    ----------
    controlled : Tensor of bool, shape (A,)
        The vehicles it drives (:func:`ego_only` for an ego).
    accel : float, default=0.0
        Acceleration [m/s^2].
    steer : float, default=0.0
        Front-wheel angle [rad].

    Examples
    --------
    >>> ConstantPolicy(ego_only(2), accel=1.0).accel
    1.0
    >>> get_policy("constant", {"accel": "-2"}, n_vehicles=2).accel  # YAML: validated
    -2.0
    """

    class Params(BaseModel):
        """``params`` of ``ego: {policy: constant}`` (see the class)."""

        model_config = ConfigDict(frozen=True)

        accel: float = 0.0
        steer: float = 0.0

    reads_lidar = False
    noise = None

    def __init__(self, controlled: Tensor, accel: float = 0.0, steer: float = 0.0):
        self.controlled = controlled
        self.accel = accel
        self.steer = steer

    def init(self, obs: Observation, params: None) -> None:
        """No memory, no parameters."""
        return None

    def act(self, obs: Observation, state: None, noise: None) -> tuple[Action, None]:
        """The fixed commands, fields of shape (B, A)."""
        x = obs.state.x
        return Action(
            accel=torch.full_like(x, self.accel), steer=torch.full_like(x, self.steer)
        ), None


_POLICIES = Registry("ego policy")


def register_policy(
    name: str, factory: Callable[..., Any], *, params: type[BaseModel] | None = None
) -> None:
    """Make ``factory`` available as ``get_policy(name, ...)``.

    ``params`` is its params model (default: ``factory.Params``, if any); see
    :meth:`avrisk.registry.Registry.register`.
    """
    _POLICIES.register(name, factory, params=params)


def get_policy(
    name: str,
    params: Mapping[str, Any] | None = None,
    /,
    *,
    allow_import: bool = False,
    **context: Any,
) -> Actor:
    """Build an ego policy by registered name or import path.

    Parameters
    ----------
    name : str
        E.g. ``"idm_mobil"``, ``"constant"``, or ``"mypkg.egos:MyEgo"``.
    params : mapping, optional
        The policy's ``params`` from a scenario, validated by its params model.
    allow_import : bool, default=False
        Whether an import path may be imported.
    **context
        The caller's arguments (``net``, ``road``, ...), passed as they are.

    Raises
    ------
    avrisk.registry.ComponentError
        If ``name`` is unknown (also a ``KeyError``; the message lists the
        known names), cannot be imported, or ``params`` do not validate; see
        :meth:`avrisk.registry.Registry.build`.
    """
    return _POLICIES.build(name, params, allow_import=allow_import, **context)


def _constant_factory(*, n_vehicles: int, **params: Any) -> ConstantPolicy:
    return ConstantPolicy(ego_only(n_vehicles), **params)


register_policy("constant", _constant_factory, params=ConstantPolicy.Params)

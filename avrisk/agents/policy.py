"""Ego policies by name, and the constant-command actor.

Every driver and ego policy here is an actor of the simulator
(:class:`avrisk.sim.interfaces.Actor`): it sets the actions of the vehicles it
``controlled``. An ego policy is an actor that controls vehicle 0 only
(:func:`ego_only`); it may use everything in the observation: the ego's own
lidar and lane features (``obs.lidar.range[:, 0]``) as a real vehicle would,
the full state as privileged information. A neural net, a vision net or a
client of an external process all fit.

Ego policies are registered by name (``"constant"``, ``"idm_mobil"``,
``"lidar_imitation"``, ``"vision_pilotnet"``) for scenario files and the command line
(:func:`get_policy`). A user's own ego may be simpler than an actor: any
object with ``init(obs) -> state`` and ``act(obs, state) -> (Action of shape
(B,), state)`` (an :class:`EgoPolicy`) drives vehicle 0 through
:class:`EgoActor`::

    class HoldSpeed:
        reads_lidar = False

        def __init__(self, speed: float = 25.0) -> None:
            self.speed = speed

        def init(self, obs):
            return None

        def act(self, obs, state):  # fields of shape (B,)
            v = obs.state.speed[:, 0]
            return Action(0.5 * (self.speed - v), torch.zeros_like(v)), None
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import torch
from pydantic import BaseModel, ConfigDict
from torch import Tensor

from avrisk.registry import Registry
from avrisk.sim.camera import reads_camera
from avrisk.sim.interfaces import Action, Actor, deterministic, reads_lidar
from avrisk.sim.observation import Observation

__all__ = [
    "POLICIES",
    "ConstantPolicy",
    "EgoActor",
    "EgoPolicy",
    "as_ego_actor",
    "ego_only",
    "get_policy",
    "register_policy",
]


def ego_only(n_vehicles: int, *, device: str | torch.device = "cpu") -> Tensor:
    """The ``controlled`` mask of an ego policy: vehicle 0 of ``n_vehicles``.

    Examples
    --------
    >>> ego_only(3).tolist()
    [True, False, False]
    """
    return torch.arange(n_vehicles, device=device) == 0


@runtime_checkable
class EgoPolicy(Protocol):
    """The simplest ego under test: the ego's action only, no noise input."""

    def init(self, obs: Observation) -> Any:
        """The policy's state for the batch, from the observation at ``t = 0``."""
        ...

    def act(self, obs: Observation, state: Any) -> tuple[Action, Any]:
        """The ego's action, fields of shape (B,), and the next state."""
        ...


class EgoActor:
    """An :class:`EgoPolicy` as the simulator's actor of vehicle 0.

    Parameters
    ----------
    policy : EgoPolicy
    n_vehicles : int
        ``A``.
    device : str or torch.device, default="cpu"

    Examples
    --------
    >>> ego = EgoActor(ConstantPolicy(ego_only(1), accel=1.0), 3)
    >>> ego.controlled.tolist(), ego.noise, ego.deterministic
    ([True, False, False], None, True)
    """

    noise = None

    def __init__(
        self, policy: Any, n_vehicles: int, *, device: str | torch.device = "cpu"
    ) -> None:
        self.policy = policy
        self.controlled = ego_only(n_vehicles, device=device)
        self.reads_lidar = reads_lidar(policy)
        self.reads_camera = reads_camera(policy)
        self.deterministic = deterministic(policy)

    def init(self, obs: Observation, params: Tensor | None) -> Any:
        """The policy's initial state (an ego policy takes no part of ``X``)."""
        return self.policy.init(obs)

    def act(self, obs: Observation, state: Any, noise: None) -> tuple[Action, Any]:
        """The policy's action in every column (only vehicle 0's is used)."""
        action, state = self.policy.act(obs, state)
        shape = obs.state.x.shape
        accel = action.accel.reshape(-1, 1).to(obs.state.x).expand(shape)
        steer = action.steer.reshape(-1, 1).to(obs.state.x).expand(shape)
        return Action(accel=accel, steer=steer), state


def as_ego_actor(
    ego: Any, n_vehicles: int, *, device: str | torch.device = "cpu"
) -> Actor:
    """``ego`` itself if it is an actor, else wrapped in :class:`EgoActor`.

    Raises
    ------
    TypeError
        If ``ego`` is neither an actor nor an :class:`EgoPolicy`.
    """
    if isinstance(ego, Actor) and hasattr(ego, "controlled"):
        return ego
    if isinstance(ego, EgoPolicy):
        return EgoActor(ego, n_vehicles, device=device)
    raise TypeError(
        f"an ego policy must have init(obs) and act(obs, state) (or be an actor "
        f"of the simulator); got {type(ego).__name__}"
    )


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


#: The ego policies by name (``"idm_mobil"``, ``"constant"``), built by
#: ``get_policy(name or "package.module:attribute", params, *, allow_import,
#: **context)`` and extended by ``register_policy(name, factory, *, params)``
#: (:class:`~avrisk.registry.Registry`). A factory is offered ``n_vehicles``,
#: ``road``, ``device``, ``dtype`` and ``net`` (the driver network or None) and
#: receives those its signature names, plus its validated params.
POLICIES = Registry("ego policy")
register_policy = POLICIES.register
get_policy = POLICIES.build


def _constant_factory(
    *,
    n_vehicles: int,
    accel: float = 0.0,
    steer: float = 0.0,
    device: str | torch.device = "cpu",
) -> ConstantPolicy:
    """The ego holding ``accel`` and ``steer`` (only the context it needs)."""
    return ConstantPolicy(ego_only(n_vehicles, device=device), accel, steer)


register_policy("constant", _constant_factory, params=ConstantPolicy.Params)

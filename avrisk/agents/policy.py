"""The ego-policy and driver-model plug-in interfaces.

A policy is a pair of pure functions over tensors (after Waymax's actor core
and BlackJAX's ``init``/``step``):

    policy_state = policy.init(obs)
    action, policy_state = policy.act(obs, policy_state)   # every step

``obs`` is an :class:`~avrisk.sim.observation.Observation` of the whole batch;
``policy_state`` is whatever the policy needs to remember (None, a tensor, a
dataclass of tensors). Two roles:

* :class:`Policy` -- the **ego** under test: returns the ego's action, fields
  of shape (B,). It may use everything in ``obs``: the ego's own lidar and
  lane features (``obs.lidar.range[:, 0]``) as a real vehicle would, the full
  state as privileged information. A neural net, a vision net or a client of an
  external process all fit.
* :class:`DriverModel` -- the **environment**: returns every vehicle's action,
  fields of shape (B, A). The simulator overrides column 0 with the ego
  policy's action when an ego policy is given.

Contract: a rollout's actions must depend only on that rollout's rows of
``obs`` and ``policy_state`` (and its seed): only elementwise work along the
batch dimension, randomness from :mod:`avrisk.tensors.noise`. That is what keeps a
rollout's result independent of the batch it shares.

Lidar on demand: scanning every vehicle's lidar is the simulator's costliest
step. A policy or driver model that never reads ``obs.lidar`` may say so with a
class attribute ``reads_lidar = False``; when neither the drivers nor the ego
read it, the simulator skips the scan and ``obs.lidar`` is None. Without the
attribute a model is assumed to read it (:func:`reads_lidar`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import torch
from torch import Tensor

from avrisk.registry import Registry
from avrisk.sim.observation import Observation
from avrisk.tensors.tensors import TensorDataclass

__all__ = [
    "Action",
    "ConstantPolicy",
    "DriverModel",
    "Policy",
    "get_policy",
    "reads_lidar",
    "register_policy",
]


@dataclass(frozen=True)
class Action(TensorDataclass):
    """Actuation commands.

    Attributes
    ----------
    accel : Tensor of shape (B,) or (B, A)
        Acceleration along the heading [m/s^2]; the simulator clips it to its
        physical limits.
    steer : Tensor of shape (B,) or (B, A)
        Front-wheel angle [rad], positive turns left; clipped likewise.
    """

    accel: Tensor  # [B] or [B, A] m/s^2
    steer: Tensor  # [B] or [B, A] rad


@runtime_checkable
class Policy(Protocol):
    """The ego policy under test (see module docstring)."""

    def init(self, obs: Observation) -> Any:
        """Initial policy state for the batch, from the observation at ``t = 0``."""
        ...

    def act(self, obs: Observation, state: Any) -> tuple[Action, Any]:
        """The ego's action, fields of shape (B,), and the next policy state."""
        ...


@runtime_checkable
class DriverModel(Protocol):
    """The environment's drivers (see module docstring)."""

    def init(self, obs: Observation) -> Any:
        """Initial driver state for the batch, from the observation at ``t = 0``."""
        ...

    def act(self, obs: Observation, state: Any) -> tuple[Action, Any]:
        """Every vehicle's action, fields of shape (B, A), and the next state."""
        ...


def reads_lidar(model: Any) -> bool:
    """Whether a policy or driver model reads ``obs.lidar`` (default True).

    Examples
    --------
    >>> reads_lidar(ConstantPolicy()), reads_lidar(object())
    (False, True)
    """
    return bool(getattr(model, "reads_lidar", True))


class ConstantPolicy:
    """An ego that holds fixed commands (cruise control, test double).

    Parameters
    ----------
    accel : float, default=0.0
        Acceleration [m/s^2].
    steer : float, default=0.0
        Front-wheel angle [rad].

    Examples
    --------
    >>> ConstantPolicy(accel=1.0).accel
    1.0
    """

    reads_lidar = False

    def __init__(self, accel: float = 0.0, steer: float = 0.0) -> None:
        self.accel = accel
        self.steer = steer

    def init(self, obs: Observation) -> None:
        """No memory."""
        return None

    def act(self, obs: Observation, state: None) -> tuple[Action, None]:
        """The fixed commands for every rollout, fields of shape (B,)."""
        x = obs.state.x[:, 0]
        return Action(
            accel=torch.full_like(x, self.accel), steer=torch.full_like(x, self.steer)
        ), None


_POLICIES = Registry("policy")


def register_policy(name: str, factory: Callable[..., Any]) -> None:
    """Make ``factory(**kwargs)`` available as ``get_policy(name, ...)``."""
    _POLICIES.register(name, factory)


def get_policy(name: str, **kwargs: Any) -> Policy:
    """Build a registered ego policy by name (e.g. ``"idm_mobil"``, ``"constant"``).

    Raises
    ------
    KeyError
        If ``name`` is not registered; the message lists the known names.
    """
    return _POLICIES.build(name, **kwargs)


def _constant_factory(**kwargs: Any) -> ConstantPolicy:
    return ConstantPolicy(**kwargs)


register_policy("constant", _constant_factory)

"""What plugs into the simulator: actors that drive vehicles, and safety measures.

The simulator owns these interfaces; :mod:`avrisk.agents` and
:mod:`avrisk.safety` implement them, and :mod:`avrisk.assembly` picks the
implementations a scenario names.

Actors
------
An actor drives some of the ``A`` vehicles of every rollout (after Waymax's
actor core and BlackJAX's ``init``/``step``). The simulator calls, for a
batch of ``B`` rollouts::

    actor_state = actor.init(obs, params)                  # t = 0
    action, actor_state = actor.act(obs, actor_state, z)   # t = 0 .. T-1

* ``obs`` is the :class:`~avrisk.sim.observation.Observation` of the whole
  batch at step ``t``; ``actor_state`` is whatever the actor remembers (None,
  a tensor, a dataclass or tuple of tensors).
* ``params`` is the actor's per-rollout parameter block, a tensor of shape
  (B, P) (for example the learned drivers' last layer ``xi``, columns of
  ``X``), or None for an actor that takes none.
* ``z`` is the step's standard-normal noise, shape (B, *noise.shape), drawn
  by the simulator from the rollouts' seeds when the actor asks for it
  (``actor.noise``, a :class:`NoiseRequest`), else None. The noise is a pure
  function of (seed, step, stream, index) (:func:`avrisk.tensors.noise.normal`).
* ``action`` has fields of shape (B, A): an actor computes every vehicle's
  action (cheap, batched) and the simulator uses the columns it
  ``controlled``. Actors are merged in order, later ones overriding earlier
  ones on the vehicles they control; every vehicle must be controlled by one.

Contracts:

* a rollout's actions depend only on that rollout's rows of ``obs``,
  ``params``, the actor state and the noise: only elementwise work along the
  batch dimension. That keeps a rollout's result independent of its batch;
* every tensor of the actor state has the batch as its leading dimension or
  is the same for every rollout, so that some rollouts of a batch can be
  restarted while the others go on
  (:meth:`~avrisk.sim.rollout.RolloutCarry.with_rows`); ``obs.step`` is then
  one index per rollout;
* an actor that cannot act for a rollout returns a non-finite action (NaN)
  for its controlled vehicles of that rollout. The simulator then stops the
  rollout there and marks it failed (``RolloutResult.status``); other
  rollouts are not affected;
* lidar on demand: scanning every vehicle's lidar is the simulator's costliest
  step. An actor that never reads ``obs.lidar`` says so with a class
  attribute ``reads_lidar = False``; when no actor reads it, the simulator
  skips the scan and ``obs.lidar`` is None. Without the attribute an actor is
  assumed to read it (:func:`reads_lidar`);
* camera on demand: the ego's camera image (``obs.camera``) is rendered only
  when an actor says ``reads_camera = True``, and only by a simulator built
  with a camera (:mod:`avrisk.sim.camera`); otherwise it is None. Without the
  attribute an actor is assumed not to read it;
* repeatability: a rollout's result must depend only on its ``X`` and its
  seed (the noise above). An actor that cannot vouch for it (an AV in another
  process, an actor drawing from a generator of its own) says so with
  ``deterministic = False``: the runs of its scenarios then evaluate a few
  rollouts twice before they start and stop where they differ
  (:mod:`avrisk.pipeline.repeatability`; every resume replays recorded
  rollouts, whatever the actors). Without the attribute an actor is taken at
  its word (:func:`deterministic`).

Safety measures
---------------
A safety measure maps a rollout to one number ``f`` per rollout, low meaning
dangerous. It is evaluated online, one state at a time, so the simulator never
keeps a rollout's history::

    carry = measure.init(measure.instant(state_0))
    carry = measure.update(carry, measure.instant(state_t), alive)  # t = 1..T
    f = measure.finalize(carry)

``instant`` maps a state (..., A) to a value (...); ``update`` must leave a
rollout's carry untouched where ``alive`` is false (it stopped).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import torch
from torch import Tensor

from avrisk.sim.observation import Observation
from avrisk.sim.state import VehicleState
from avrisk.tensors.tensors import TensorDataclass

__all__ = [
    "Action",
    "Actor",
    "NoiseRequest",
    "SafetyMeasure",
    "reads_lidar",
    "weights_files",
]


@dataclass(frozen=True)
class Action(TensorDataclass):
    """Actuation commands of every vehicle of a batch.

    Attributes
    ----------
    accel : Tensor of shape (B, A)
        Acceleration along the heading [m/s^2]; the simulator clips it to its
        physical limits.
    steer : Tensor of shape (B, A)
        Front-wheel angle [rad], positive turns left; clipped likewise.
    """

    accel: Tensor  # [B, A] m/s^2
    steer: Tensor  # [B, A] rad


@dataclass(frozen=True)
class NoiseRequest:
    """The standard-normal noise an actor consumes at every step.

    Attributes
    ----------
    stream : int
        Counter-based noise stream (``>= 0``), one constant per use.
    shape : tuple of int
        Per-rollout shape: the actor receives a tensor of shape (B, *shape).
    dtype : torch.dtype or None, default=None
        Floating type the noise is drawn in (the numbers depend on it); None
        draws in the simulator's dtype.

    Examples
    --------
    >>> NoiseRequest(stream=7, shape=(6, 2))
    NoiseRequest(stream=7, shape=(6, 2), dtype=None)
    """

    stream: int
    shape: tuple[int, ...]
    dtype: torch.dtype | None = None


@runtime_checkable
class Actor(Protocol):
    """Drives the vehicles it controls (see the module docstring)."""

    #: Bool tensor of shape (A,): the vehicles whose action this actor sets.
    controlled: Tensor
    #: Whether :meth:`act` reads ``obs.lidar`` (optional; default True).
    reads_lidar: bool
    #: The per-step noise :meth:`act` receives, or None for none.
    noise: NoiseRequest | None
    #: Learned-weights files it acts by, name -> path (optional; default none):
    #: :func:`weights_files`.

    def init(self, obs: Observation, params: Tensor | None) -> Any:
        """Initial actor state, from the observation at ``t = 0`` and ``params``."""
        ...

    def act(
        self, obs: Observation, state: Any, noise: Tensor | None
    ) -> tuple[Action, Any]:
        """Actions with fields of shape (B, A) and the next actor state."""
        ...


def reads_lidar(actor: Any) -> bool:
    """Whether an actor reads ``obs.lidar`` (its ``reads_lidar``, default True).

    Examples
    --------
    >>> class Blind:
    ...     reads_lidar = False
    >>> reads_lidar(Blind()), reads_lidar(object())
    (False, True)
    """
    return bool(getattr(actor, "reads_lidar", True))


def deterministic(actor: Any) -> bool:
    """Whether an actor vouches that it is repeatable (``deterministic``, or True)."""
    return bool(getattr(actor, "deterministic", True))


def weights_files(actor: Any) -> dict[str, Path]:
    """The learned-weights files an actor acts by (``weights_files``, or none).

    An actor loaded from files names them (file name -> path), so that a
    provenance stamp hashes what defines its behaviour.

    Examples
    --------
    >>> weights_files(object())
    {}
    """
    return dict(getattr(actor, "weights_files", {}))


@runtime_checkable
class SafetyMeasure(Protocol):
    """What the simulator needs of a safety measure (see the module docstring)."""

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

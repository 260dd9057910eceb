"""What a batch of rollouts carries from step to step, and what it returns.

:class:`RolloutCarry` is the input and output of the simulator's pure step
function; :class:`RolloutResult` the outcome of a batch (the safety measure
``f``, crash, road departure, reversing, the steps simulated, a
:class:`Status` per rollout) and :class:`Trace` its trajectories, when
recorded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, NamedTuple

import torch
from torch import Tensor

from avrisk.sim.sensing import Geometry
from avrisk.sim.state import VehicleState
from avrisk.tensors.rows import replace_rows

__all__ = [
    "RolloutCarry",
    "RolloutResult",
    "Status",
    "Trace",
    "stack_trace",
    "trace_frame",
]


@dataclass(frozen=True)
class Trace:
    """Recorded trajectories of a batch, for animation and inspection.

    Frame ``t`` is the state at time ``t * dt``; after a rollout stops, its
    frames repeat the stopping state and ``alive`` is false.

    Attributes
    ----------
    x, y, heading, speed : Tensor of shape (B, T+1, A)
        As in :class:`~avrisk.sim.state.VehicleState` [m, m, rad, m/s].
    alive : Tensor of bool, shape (B, T+1)
        ``alive[b, t]`` iff ``t <= steps[b]``: frame ``t`` was simulated.
    ttc : Tensor of shape (B, T+1)
        Instantaneous TTC at each frame [s]; ``inf`` where not alive.
    """

    x: Tensor  # [B, T+1, A] m
    y: Tensor  # [B, T+1, A] m
    heading: Tensor  # [B, T+1, A] rad
    speed: Tensor  # [B, T+1, A] m/s
    alive: Tensor  # [B, T+1] bool
    ttc: Tensor  # [B, T+1] s


class Status(IntEnum):
    """Per-rollout status codes (``RolloutResult.status``, int8)."""

    #: Simulated to its crash or to the horizon.
    OK = 0
    #: An actor returned a non-finite action for it: stopped there, ``f`` NaN.
    ACTOR_FAILED = 1


@dataclass(frozen=True)
class RolloutResult:
    """Outcome of a batch of rollouts.

    Attributes
    ----------
    f : Tensor of shape (B,)
        The safety measure, e.g. minimum TTC over time [s]; ``inf`` if nothing
        ever approached; NaN where ``status`` is not ``OK``.
    crash : Tensor of bool, shape (B,)
        The ego collided (the rollout stopped there).
    offroad : Tensor of bool, shape (B,)
        A corner of the ego was beyond a road edge at some simulated step.
    reversing : Tensor of bool, shape (B,)
        The ego moved against the road direction at some simulated step.
    steps : Tensor of int64, shape (B,)
        Steps simulated: the crash step, the last step before an actor
        failed, or ``T`` (0 if it starts in a crash).
    status : Tensor of int8, shape (B,)
        :class:`Status` code: 0 ok, 1 an actor failed for this rollout.
    collision_with : Tensor of int64, shape (B,)
        Vehicle the ego crashed into (lowest index if several); -1 if none.
    contact : Tensor of int8, shape (B,)
        :class:`~avrisk.sim.collision.Contact` mechanism of the crash, from
        the relative position at the crash step: 0 none, 1 the ego rear-ends
        the vehicle ahead in its lane-width band, 2 hit from behind, 3 side
        contact.
    trace : Trace or None
        Trajectories, when requested.
    """

    f: Tensor  # [B] s
    crash: Tensor  # [B] bool
    offroad: Tensor  # [B] bool
    reversing: Tensor  # [B] bool
    steps: Tensor  # [B] int64
    status: Tensor  # [B] int8
    collision_with: Tensor  # [B] int64
    contact: Tensor  # [B] int8
    trace: Trace | None = None


class RolloutCarry(NamedTuple):
    """What a batch of rollouts carries from one step to the next.

    The input and output of :meth:`~avrisk.sim.simulator.Simulator.step`:
    tensors (and the actors' states) only, so that the step is a pure function.

    Attributes
    ----------
    state : VehicleState
        Fields of shape (B, A), frozen where the rollout stopped.
    geo : tuple of Tensor
        What ``state`` implies short of ray casting (headings' cosines and
        sines (B, A), pairwise overlap (B, A, A), road departure and reversing
        flags (B, A), lane features (B, A)).
    actors : tuple
        Each actor's state, in the order of the actors.
    measure : Tensor of shape (B,)
        The safety measure's carry.
    alive : Tensor of bool, shape (B,)
        Still simulated (no crash, no actor failure).
    crash, offroad, reversing : Tensor of bool, shape (B,)
        As in :class:`RolloutResult`, so far.
    steps : Tensor of int64, shape (B,)
        Steps simulated so far.
    status : Tensor of int8, shape (B,)
    partner : Tensor of int64, shape (B,)
        ``collision_with`` so far (-1: none).
    contact : Tensor of int8, shape (B,)
    """

    state: VehicleState
    geo: Geometry
    actors: tuple[Any, ...]
    measure: Tensor  # [B]
    alive: Tensor  # [B] bool
    crash: Tensor  # [B] bool
    offroad: Tensor  # [B] bool
    reversing: Tensor  # [B] bool
    steps: Tensor  # [B] int64
    status: Tensor  # [B] int8
    partner: Tensor  # [B] int64
    contact: Tensor  # [B] int8

    def with_rows(self, rows: Tensor, fresh: RolloutCarry) -> RolloutCarry:
        """The carry with some rollouts restarted, the others untouched.

        Parameters
        ----------
        rows : Tensor of bool, shape (B,)
            The rollouts to restart; ``n`` of them are true.
        fresh : RolloutCarry
            ``n`` rollouts at ``t = 0``
            (:meth:`~avrisk.sim.simulator.Simulator.start`), in the order of
            ``rows``, from the same actors' ``init``. Their steps count from 0
            again: step the batch with a step index per rollout
            (:meth:`~avrisk.sim.simulator.Simulator.step` takes ``t`` of shape
            (B,)).

        Returns
        -------
        RolloutCarry

        Raises
        ------
        ValueError
            If an actor's state has a tensor that is neither per rollout
            (leading dimension ``B``) nor the same for every rollout.
        """
        return replace_rows(self, rows, fresh)


def trace_frame(state: VehicleState, alive: Tensor, ttc: Tensor) -> tuple[Tensor, ...]:
    """One frame of a :class:`Trace` (``ttc`` already ``inf`` where not alive)."""
    return (state.x, state.y, state.heading, state.speed, alive, ttc)


def stack_trace(frames: list[tuple[Tensor, ...]], n_steps: int) -> Trace:
    """The recorded frames stacked, padded to ``T + 1`` if all stopped early."""
    while len(frames) < n_steps + 1:  # everyone stopped early
        x, y, heading, speed, live, t = frames[-1]
        dead = torch.zeros_like(live)
        frames.append((x, y, heading, speed, dead, torch.full_like(t, math.inf)))
    return Trace(*(torch.stack(parts, dim=1) for parts in zip(*frames, strict=True)))

"""The actors of a simulator: their masks checked, their actions combined.

Every vehicle is driven by the last actor whose ``controlled`` mask holds it
(:mod:`avrisk.sim.interfaces`); an actor that asks for noise gets the step's
counter-based standard normals (:mod:`avrisk.tensors.noise`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor

from avrisk.sim.camera import reads_camera
from avrisk.sim.interfaces import Actor, NoiseRequest
from avrisk.sim.observation import Observation
from avrisk.sim.sensing import any_reads_camera
from avrisk.tensors.noise import normal

__all__ = ["act", "actor_noise", "controlled_masks"]


def controlled_masks(
    actors: Sequence[Actor],
    n_vehicles: int,
    device: torch.device,
    *,
    has_camera: bool,
) -> list[Tensor]:
    """Every actor's ``controlled`` mask on the device, checked.

    Parameters
    ----------
    actors : sequence of Actor
    n_vehicles : int
        ``A``.
    device : torch.device
    has_camera : bool
        Whether the simulator has a camera for actors that read it.

    Returns
    -------
    list of Tensor of bool, shape (A,)
        The masks :meth:`avrisk.sim.simulator.Simulator.step` takes.

    Raises
    ------
    ValueError
        For no actor, a mask that is not a bool tensor of shape (A,), a
        vehicle that no actor controls, or an actor that reads the camera
        of a simulator without one.
    """
    if not actors:
        raise ValueError("give at least one actor")
    if not has_camera and any_reads_camera(actors):
        names = [type(a).__name__ for a in actors if reads_camera(a)]
        raise ValueError(
            f"{', '.join(names)} reads the camera, and this simulator has none; "
            "build the Simulator with camera=... (avrisk.render.RayCastCamera)"
        )
    masks = []
    for k, actor in enumerate(actors):
        mask = torch.as_tensor(actor.controlled)
        if mask.dtype != torch.bool or mask.shape != (n_vehicles,):
            raise ValueError(
                f"actor {k} ({type(actor).__name__}): controlled must be a bool "
                f"tensor of shape ({n_vehicles},); got {mask.dtype} of shape "
                f"{tuple(mask.shape)}"
            )
        masks.append(mask.to(device))
    covered = torch.stack(masks).any(dim=0)
    if not bool(covered.all()):
        missing = torch.nonzero(~covered).flatten().tolist()
        raise ValueError(
            f"vehicles {missing} are controlled by no actor; every vehicle "
            "needs one (set its entry of some actor's controlled)"
        )
    return masks


def actor_noise(
    request: NoiseRequest | None, obs: Observation, dtype: torch.dtype
) -> Tensor | None:
    """The step's standard-normal noise for one actor, (B, *shape), or None."""
    if request is None:
        return None
    dtype = dtype if request.dtype is None else request.dtype
    return normal(obs.seeds, obs.step, request.stream, request.shape, dtype=dtype)


def act(
    obs: Observation,
    actors: Sequence[Actor],
    masks: Sequence[Tensor],
    states: Sequence[Any],
    dtype: torch.dtype,
) -> tuple[Tensor, Tensor, tuple[Any, ...]]:
    """Every vehicle's (accel, steer), (B, A), from its controlling actor.

    A vehicle takes the action of the last actor whose ``masks`` entry
    holds it; the actions are cast to ``dtype``. Returns the actions and
    the actors' next states.
    """
    accel = steer = None
    new_states = []
    for actor, mask, memory in zip(actors, masks, states, strict=True):
        action, memory = actor.act(obs, memory, actor_noise(actor.noise, obs, dtype))
        new_states.append(memory)
        mine = action.accel.to(dtype), action.steer.to(dtype)
        if accel is None or steer is None:
            accel, steer = mine
        else:
            accel = torch.where(mask, mine[0], accel)
            steer = torch.where(mask, mine[1], steer)
    assert accel is not None and steer is not None
    return accel, steer, tuple(new_states)

"""A reference AV process in Python: binds a REP socket and drives the ego.

:class:`EgoServer` answers the protocol's messages (``docs/ego-protocol.md``)
with the actions of a controller; :func:`serve` runs it on a socket
(``avrisk serve-ego``). :class:`AccController` is the controller shipped: an
IDM-like adaptive cruise control on the ego's forward lidar beams, with lane
keeping. It uses only ``+ - * /`` and square roots in float64, so the C++
reference server (``examples/ego_server_cpp``) computes the same actions, bit
for bit. With ``noise > 0`` it adds a uniform acceleration noise drawn from
each rollout's seed and step: a stochastic AV made repeatable by the seeds of
``reset``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from avrisk.agents.external.params import DEFAULT_ADDRESS, DEFAULT_MAX_MESSAGE_BYTES
from avrisk.agents.external.protocol import (
    PROTOCOL_VERSION,
    ProtocolError,
    decode,
    encode,
    pack_array,
    unpack_array,
)
from avrisk.agents.external.spaces import hello_message, observation_arrays
from avrisk.extras import needs_extra
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = ["AccController", "EgoServer", "LocalEgo", "serve"]

_MASK64 = (1 << 64) - 1


@dataclass(frozen=True)
class AccController:
    """IDM-like adaptive cruise control with lane keeping, from lidar and lanes.

    The gap ahead is the shortest range of the beams within ``cone`` [rad] of
    the heading minus half the ego's length; the closing speed is minus that
    beam's range rate. Then IDM: ``a = a_max (1 - (v / v0)^4 - (s* / gap)^2)``
    with ``s* = s0 + max(0, v T + v dv / (2 sqrt(a_max b)))``; steering holds
    the lane: ``-(k_y lateral_offset + k_psi heading_offset)``.

    Attributes
    ----------
    speed : float
        Wanted speed ``v0`` [m/s].
    time_headway, min_gap : float
        ``T`` [s], ``s0`` [m].
    max_accel, comfort_decel : float
        ``a_max``, ``b`` [m/s^2].
    cone : float
        Half-width of the forward cone of beams [rad].
    k_lateral, k_heading : float
        Lane-keeping gains [rad/m], [rad/rad].
    noise : float
        Half-width of a uniform acceleration noise [m/s^2] (0: deterministic).
    """

    speed: float = 30.0
    time_headway: float = 1.5
    min_gap: float = 2.0
    max_accel: float = 1.5
    comfort_decel: float = 2.0
    cone: float = 0.2
    k_lateral: float = 0.04
    k_heading: float = 0.8
    noise: float = 0.0

    def act(
        self,
        obs: dict[str, np.ndarray],
        angles: np.ndarray,
        seeds: np.ndarray,
        step: int,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Actions of a batch, float64 arrays of shape (B,).

        Parameters
        ----------
        obs : dict of str to ndarray
            The step's observation (``lidar_range`` etc., batch first).
        angles : ndarray of shape (R,)
            Beam angles from the heading [rad].
        seeds : ndarray of int64, shape (B,)
            The rollouts' seeds (from ``reset``).
        step : int
        """
        v = obs["speed"].astype(np.float64)
        ahead = np.abs(np.where(angles > math.pi, angles - 2 * math.pi, angles))
        ahead = ahead <= self.cone
        free = np.full(len(v), np.inf)
        gap, closing = free, np.zeros(len(v))
        if "lidar_range" in obs and ahead.any():
            ranges = obs["lidar_range"][:, ahead].astype(np.float64)
            beam = np.argmin(ranges, axis=1)
            rows = np.arange(len(v))
            gap = ranges[rows, beam] - 0.5 * obs["length"].astype(np.float64)
            closing = -obs["lidar_range_rate"][:, ahead][rows, beam].astype(np.float64)
        ratio = v / self.speed
        ratio2 = ratio * ratio
        brake = 2.0 * math.sqrt(self.max_accel * self.comfort_decel)
        wanted = self.min_gap + np.maximum(
            0.0, v * self.time_headway + v * closing / brake
        )
        interaction = wanted / np.maximum(gap, 0.1)
        accel = self.max_accel * (1.0 - ratio2 * ratio2 - interaction * interaction)
        if self.noise > 0:
            accel = accel + self.noise * _uniform(seeds, step)
        lateral = obs["lateral_offset"].astype(np.float64)
        heading = obs["heading_offset"].astype(np.float64)
        steer = -(self.k_lateral * lateral + self.k_heading * heading)
        return accel, steer


def _uniform(seeds: np.ndarray, step: int) -> np.ndarray:
    """Uniform numbers in [-1, 1), a pure function of (seed, step) (splitmix64)."""
    z = seeds.astype(np.uint64) + np.uint64((step + 1) * 0x9E3779B97F4A7C15 & _MASK64)
    with np.errstate(over="ignore"):
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * 2.0**-52 - 1.0


class LocalEgo:
    """A controller of the AV side run in this process, without the wire.

    The same actions as over the protocol (the same arrays reach the
    controller): an in-process reference for tests and benchmarks. An
    :class:`~avrisk.agents.policy.EgoPolicy`.

    Parameters
    ----------
    controller : AccController
        Or any object with the same ``act``.
    """

    def __init__(self, controller: Any) -> None:
        self.controller = controller

    def init(self, obs: Observation) -> np.ndarray:
        """The batch's seeds, shape (B,)."""
        return obs.seeds.detach().cpu().numpy()

    def act(self, obs: Observation, state: np.ndarray) -> tuple[Action, np.ndarray]:
        """The controller's actions, fields of shape (B,)."""
        arrays = observation_arrays(obs)
        angles = np.asarray(hello_message(arrays, obs.dt)["lidar_angles"])
        accel, steer = self.controller.act(arrays, angles, state, obs.step)
        return Action(torch.from_numpy(accel), torch.from_numpy(steer)), state


class EgoServer:
    """The AV side of the protocol around a controller (see the module docstring).

    Parameters
    ----------
    controller : AccController
        Or any object with the same ``act``.
    name : str, default="avrisk-reference-python"
        Reported in the handshake.
    max_message_bytes : int, default=64 MiB
        Largest request accepted [bytes].
    """

    def __init__(
        self,
        controller: Any,
        *,
        name: str = "avrisk-reference-python",
        max_message_bytes: int = DEFAULT_MAX_MESSAGE_BYTES,
    ) -> None:
        self.controller = controller
        self.name = name
        self.max_bytes = max_message_bytes
        self.spaces: dict[str, tuple[str, tuple[int, ...]]] = {}
        self.angles = np.zeros(0)
        self.episode: int | None = None
        self.seeds = np.zeros(0, dtype=np.int64)

    def handle(self, raw: bytes) -> bytes:
        """The reply to one request; a bad request gets an ``error`` reply."""
        try:
            reply = self.reply(decode(raw, self.max_bytes))
        except ProtocolError as err:
            reply = {"type": "error", "message": str(err)}
        return encode(reply)

    def reply(self, message: dict[str, Any]) -> dict[str, Any]:
        """The reply to one decoded request.

        Raises
        ------
        ProtocolError
            For a request out of order or not as the handshake described.
        """
        kind = message["type"]
        if kind == "hello":
            return self._hello(message)
        if kind == "reset":
            if not self.spaces:
                raise ProtocolError("reset before hello")
            seeds = message.get("seeds")
            shape = seeds.get("shape") if isinstance(seeds, dict) else None
            if not (isinstance(shape, list) and len(shape) == 1):
                raise ProtocolError("reset: seeds must be an array of shape (B,)")
            self.seeds = unpack_array(seeds, "seeds", dtypes=("i8",), shape=(shape[0],))
            self.episode = message.get("episode")
            return {"type": "reset", "episode": self.episode}
        if kind == "step":
            return self._step(message)
        raise ProtocolError(f"unknown message type {kind!r}")

    def _hello(self, message: dict[str, Any]) -> dict[str, Any]:
        if message.get("protocol") != PROTOCOL_VERSION:
            raise ProtocolError(
                f"protocol {message.get('protocol')!r} requested; this server "
                f"speaks {PROTOCOL_VERSION}"
            )
        fields = message.get("observation")
        if not isinstance(fields, dict):
            raise ProtocolError("hello: no observation space")
        self.spaces = {
            name: (spec["dtype"], tuple(spec["shape"])) for name, spec in fields.items()
        }
        self.angles = np.asarray(message.get("lidar_angles", []), dtype=np.float64)
        return {"type": "hello", "protocol": PROTOCOL_VERSION, "server": self.name}

    def _step(self, message: dict[str, Any]) -> dict[str, Any]:
        if self.episode is None or message.get("episode") != self.episode:
            raise ProtocolError(
                f"step for episode {message.get('episode')!r}, not reset"
            )
        step = message.get("step")
        obs = message.get("obs")
        if not isinstance(step, int) or not isinstance(obs, dict):
            raise ProtocolError("step: needs an int 'step' and a map 'obs'")
        size = len(self.seeds)
        arrays = {
            name: unpack_array(
                obs.get(name), name, dtypes=(dtype,), shape=(size, *shape)
            )
            for name, (dtype, shape) in self.spaces.items()
        }
        accel, steer = self.controller.act(arrays, self.angles, self.seeds, step)
        return {
            "type": "step",
            "episode": self.episode,
            "step": step,
            "accel": pack_array(accel),
            "steer": pack_array(steer),
        }


def serve(
    server: EgoServer, address: str = DEFAULT_ADDRESS, *, ready: Any = None
) -> None:
    """Bind a REP socket at ``address`` and answer requests until interrupted.

    ``ready``, if given, is called once the socket is bound (e.g. to print it).
    """
    with needs_extra("external", "the external ego"):
        import zmq

    context = zmq.Context.instance()
    socket = context.socket(zmq.REP)
    socket.setsockopt(zmq.LINGER, 0)
    socket.setsockopt(zmq.MAXMSGSIZE, server.max_bytes)
    socket.bind(address)
    if ready is not None:
        ready(address)
    try:
        while True:
            socket.send(server.handle(socket.recv()))
    finally:
        socket.close(linger=0)

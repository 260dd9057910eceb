"""The ``external`` ego policy: an AV in another process, over ZeroMQ.

avrisk is the client (a REQ socket that connects); the AV process binds a REP
socket. Per batch of ``B`` rollouts: ``hello`` (handshake), ``reset`` (one seed
per rollout), then one ``step`` per time step with the batch's observations,
answered by the batch's actions (``docs/ego-protocol.md``).

Faults are results, never silence: when the AV does not answer within
``timeout_s``, answers with something malformed, mis-shaped or too large, or
reports an error, the rollouts of the batch still running get a non-finite
action: the simulator marks them failed (``status``), the reason is kept in
:attr:`ExternalEgo.failure_reasons` (the samples table's ``failure`` column)
and logged. A non-finite action fails its rollout only. After a timeout the
socket is closed and opened again (ZeroMQ's "lazy pirate" pattern), so the
next batch talks to the AV afresh, e.g. once it has been restarted.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from avrisk.agents.external.params import ExternalParams
from avrisk.agents.external.protocol import (
    PROTOCOL_VERSION,
    ProtocolError,
    decode,
    encode,
    pack_array,
    unpack_array,
)
from avrisk.agents.external.spaces import hello_message, observation_arrays
from avrisk.agents.policy import ego_only
from avrisk.extras import needs_extra
from avrisk.sim.interfaces import Action
from avrisk.sim.observation import Observation

__all__ = ["EgoFault", "Episode", "ExternalEgo"]

#: A reply may hold this much besides its actions [bytes], plus 32 per rollout.
_REPLY_OVERHEAD = 64 * 1024
_log = logging.getLogger(__name__)


class EgoFault(Exception):
    """The AV did not give a usable answer for a batch (the text says why)."""


@dataclass
class Episode:
    """The actor state of one batch: its number and the fault that ended it."""

    number: int
    size: int
    fault: str | None = None


class _Link:
    """One REQ socket to the AV, closed and opened again after a timeout."""

    def __init__(self, address: str, timeout_s: float, max_bytes: int) -> None:
        with needs_extra("external", "the external ego"):
            import zmq
        self._zmq = zmq
        self._context = zmq.Context.instance()
        self.address = address
        self.timeout_s = timeout_s
        self.max_bytes = max_bytes
        self._socket: Any = None

    def request(self, message: dict[str, Any], reply_limit: int) -> dict[str, Any]:
        """Send ``message``; its reply, checked to be a message of the same type.

        Raises
        ------
        EgoFault
            For a request or reply over the size limits, no reply within
            ``timeout_s`` (the socket is then reopened), a malformed reply, an
            ``error`` reply or a reply of another type.
        """
        raw = encode(message)
        if len(raw) > self.max_bytes:
            raise EgoFault(
                f"a {message['type']} request of {len(raw)} bytes is over "
                f"max_message_bytes={self.max_bytes}; use a smaller --batch-size"
            )
        socket = self._connected()
        if not socket.poll(self.timeout_s * 1000, self._zmq.POLLOUT):
            self.close()
            raise EgoFault(f"could not send to the AV at {self.address}")
        socket.send(raw)
        if not socket.poll(self.timeout_s * 1000, self._zmq.POLLIN):
            self.close()  # lazy pirate: a fresh socket for the next request
            raise EgoFault(
                f"no reply to {message['type']} within {self.timeout_s} s from "
                f"{self.address} (the AV is down or too slow, or its reply was "
                f"over {self.max_bytes} bytes)"
            )
        reply_raw = socket.recv()
        try:
            reply = decode(reply_raw, min(reply_limit, self.max_bytes))
        except ProtocolError as err:
            raise EgoFault(f"bad reply to {message['type']}: {err}") from None
        if reply["type"] == "error":
            raise EgoFault(f"the AV reported an error: {reply.get('message')!r}")
        if reply["type"] != message["type"]:
            raise EgoFault(f"a {reply['type']!r} reply to {message['type']}")
        return reply

    def _connected(self) -> Any:
        if self._socket is None:
            zmq = self._zmq
            self._socket = self._context.socket(zmq.REQ)
            self._socket.setsockopt(zmq.LINGER, 0)
            self._socket.setsockopt(zmq.MAXMSGSIZE, self.max_bytes)
            self._socket.connect(self.address)
        return self._socket

    def close(self) -> None:
        """Close the socket (a later request opens a new one)."""
        if self._socket is not None:
            self._socket.close(linger=0)
            self._socket = None


class ExternalEgo:
    """The ego (vehicle 0) driven by an AV process over ZeroMQ.

    Parameters
    ----------
    n_vehicles : int
        ``A``.
    params : ExternalParams
        Address, timeout and size limit.
    device : str or torch.device, default="cpu"

    Attributes
    ----------
    failure_reasons : ndarray of object (str), shape (B,)
        For the batch last simulated: why the AV gave no action for each
        rollout ("" where it did). Only rollouts that were still running
        when it failed are failed rollouts.
    """

    noise = None
    reads_lidar = True
    #: What another process computes cannot be vouched for: runs check it
    #: (:mod:`avrisk.pipeline.repeatability`).
    deterministic = False

    def __init__(
        self,
        n_vehicles: int,
        params: ExternalParams,
        *,
        device: str | torch.device = "cpu",
    ) -> None:
        self.controlled = ego_only(n_vehicles, device=device)
        self.link = _Link(params.address, params.timeout_s, params.max_message_bytes)
        self.failure_reasons = np.full(0, "", dtype=object)
        self._episodes = 0

    def init(self, obs: Observation, params: Tensor | None) -> Episode:
        """Handshake and reset the AV for this batch, one seed per rollout."""
        size = obs.seeds.shape[0]
        self._episodes += 1
        episode = Episode(self._episodes, size)
        self.failure_reasons = np.full(size, "", dtype=object)
        seeds = obs.seeds.detach().cpu().numpy()
        try:
            hello = self._request(hello_message(observation_arrays(obs), obs.dt), size)
            if hello.get("protocol") != PROTOCOL_VERSION:
                raise EgoFault(
                    f"the AV speaks protocol {hello.get('protocol')!r}, avrisk "
                    f"{PROTOCOL_VERSION}"
                )
            reply = self._request(
                {
                    "type": "reset",
                    "episode": episode.number,
                    "seeds": pack_array(seeds),
                },
                size,
            )
            if reply.get("episode") != episode.number:
                raise EgoFault(f"reset reply for episode {reply.get('episode')!r}")
        except EgoFault as fault:
            self._fail(episode, str(fault))
        return episode

    def act(
        self, obs: Observation, state: Episode, noise: None
    ) -> tuple[Action, Episode]:
        """The AV's actions for the batch; NaN for rollouts it gave none."""
        size = state.size
        accel = steer = np.full(size, np.nan)
        if state.fault is None:
            message = {
                "type": "step",
                "episode": state.number,
                "step": obs.step,
                "obs": {k: pack_array(v) for k, v in observation_arrays(obs).items()},
            }
            try:
                reply = self._request(message, size)
                if (reply.get("episode"), reply.get("step")) != (
                    state.number,
                    obs.step,
                ):
                    raise EgoFault("a step reply for another episode or step")
                accel, steer = (
                    unpack_array(
                        reply.get(name), name, dtypes=("f4", "f8"), shape=(size,)
                    )
                    for name in ("accel", "steer")
                )
            except ProtocolError as err:
                self._fail(state, f"bad step reply: {err}")
            except EgoFault as fault:
                self._fail(state, str(fault))
        bad = ~(np.isfinite(accel) & np.isfinite(steer))
        self.failure_reasons[bad & (self.failure_reasons == "")] = (
            f"non-finite action from the AV at step {obs.step}"
        )
        shape = obs.state.x.shape

        def column(values: np.ndarray) -> Tensor:
            t = torch.from_numpy(np.array(values, dtype=np.float64))
            return t.to(obs.state.x).reshape(-1, 1).expand(shape)

        return Action(accel=column(accel), steer=column(steer)), state

    def _request(self, message: dict[str, Any], size: int) -> dict[str, Any]:
        return self.link.request(message, _REPLY_OVERHEAD + 32 * size)

    def _fail(self, episode: Episode, reason: str) -> None:
        """End the batch: its rollouts still running fail with ``reason``."""
        episode.fault = reason
        self.failure_reasons[self.failure_reasons == ""] = reason
        _log.warning(
            "external ego: %s; the %d rollouts of this batch still running fail "
            "(retried when the run resumes)",
            reason,
            episode.size,
        )

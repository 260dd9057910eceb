"""AV processes for the external-ego tests: the reference one, and faulty ones.

Run as a script, ``python tests/cli/ego_servers.py ADDRESS MODE``, it serves
the reference controller with one fault (:data:`FAULTS`) in the run's second batch;
``in_thread`` serves one in a thread of the test process instead.
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import os
import sys
import threading
import time

import msgpack
import numpy as np
import pydantic
import zmq

from avrisk.agents.external.protocol import decode, encode, pack_array
from avrisk.agents.external.server import AccController, EgoServer, LocalEgo

#: The faulty batch: the run's second (after the repeatability check's two).
FAULTY_BATCH = 4


class InProcessAcc(LocalEgo):
    """The reference controller in process (``tests.cli.ego_servers:InProcessAcc``)."""

    class Params(pydantic.BaseModel):
        noise: float = 0.0

    def __init__(self, noise: float = 0.0) -> None:
        super().__init__(AccController(noise=noise))


@dataclasses.dataclass(frozen=True)
class LateBrakingController(AccController):
    """The reference controller braking 10% later: it sees gaps 10% longer."""

    def act(self, obs, angles, seeds, step):  # noqa: D102
        if "lidar_range" in obs:
            obs = {**obs, "lidar_range": obs["lidar_range"] / 0.9}
        return super().act(obs, angles, seeds, step)


class LateBrakingAcc(LocalEgo):
    """:class:`InProcessAcc` braking 10% later (an edit of the user's ego)."""

    Params = InProcessAcc.Params

    def __init__(self, noise: float = 0.0) -> None:
        super().__init__(LateBrakingController(noise=noise))


class UnvouchedAcc(InProcessAcc):
    """The same, declaring that it may not be repeatable (runs check it)."""

    deterministic = False


def _sleep(reply, server):
    time.sleep(server.timeout_s * 1.5)  # the next batch finds it awake
    return reply


def _nan(reply, server):
    accel = np.frombuffer(reply["accel"]["data"]).copy()
    accel[0] = np.nan
    reply["accel"] = pack_array(accel)
    return reply


def _unrepeatable(reply, server):
    accel = np.frombuffer(reply["accel"]["data"]) + np.random.default_rng().normal()
    reply["accel"] = pack_array(accel)
    return reply


#: mode -> what becomes of a step reply of the faulty batch (the wire bytes);
#: mode "die": the process exits at the first step of that batch.
FAULTS = {
    "sleep": lambda reply, server: encode(_sleep(reply, server)),
    "garbage": lambda reply, server: b"\xc1 not msgpack",
    "shape": lambda reply, server: encode(
        {**reply, "accel": pack_array(np.zeros(len(server.seeds) + 1))}
    ),
    "nan": lambda reply, server: encode(_nan(reply, server)),
    "oversized": lambda reply, server: encode({**reply, "pad": bytes(2**20)}),
    "error": lambda reply, server: encode(
        {"type": "error", "message": "planner crashed"}
    ),
    "unrepeatable": lambda reply, server: encode(_unrepeatable(reply, server)),
}


class FaultyServer(EgoServer):
    """The reference server with one fault in one batch (mode "none": none).

    ``batch``: the faulty batch's number; ``controller``: another AV.
    """

    def __init__(
        self,
        mode: str,
        timeout_s: float = 0.5,
        *,
        batch: int = FAULTY_BATCH,
        controller: AccController | None = None,
    ) -> None:
        super().__init__(controller or AccController())
        self.mode, self.timeout_s, self.batches = mode, timeout_s, 0
        self.faulty_batch = batch

    def handle(self, raw: bytes) -> bytes:
        message = decode(raw, self.max_bytes)
        self.batches += message["type"] == "reset"
        reply = super().handle(raw)
        faulty = self.mode == "unrepeatable" or self.batches == self.faulty_batch
        if message["type"] != "step" or not faulty or self.mode == "none":
            return reply
        if self.mode == "die":
            os._exit(3)
        return FAULTS[self.mode](msgpack.unpackb(reply), self)


def serve_until(server: EgoServer, socket, stop: threading.Event) -> None:
    """Answer requests on a bound REP socket until ``stop`` is set."""
    while not stop.is_set():
        if socket.poll(50):
            socket.send(server.handle(socket.recv()))
    socket.close(linger=0)


def _bind(socket: zmq.Socket, address: str, wait_s: float = 5.0) -> None:
    """Bind, waiting while a socket just closed at ``address`` still holds it.

    ZeroMQ closes sockets in its I/O thread, after ``close`` returns, so a
    server restarted at once at the same address may find it still in use.
    """
    deadline = time.monotonic() + wait_s
    while True:
        try:
            socket.bind(address)
            return
        except zmq.ZMQError as err:
            if err.errno != errno.EADDRINUSE or time.monotonic() > deadline:
                raise
            time.sleep(0.05)


@contextlib.contextmanager
def in_thread(server: EgoServer, address: str):
    """Serve ``server`` at ``address`` in a thread while the block runs."""
    socket = zmq.Context.instance().socket(zmq.REP)
    socket.setsockopt(zmq.LINGER, 0)
    _bind(socket, address)
    stop = threading.Event()
    thread = threading.Thread(target=serve_until, args=(server, socket, stop))
    thread.start()
    try:
        yield server
    finally:
        stop.set()
        thread.join()


if __name__ == "__main__":
    address, mode = sys.argv[1], sys.argv[2]
    socket = zmq.Context.instance().socket(zmq.REP)
    socket.bind(address)
    print("serving", flush=True)
    serve_until(FaultyServer(mode), socket, threading.Event())

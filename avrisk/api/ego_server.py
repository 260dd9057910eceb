"""The reference AV as a process of its own, as ``avrisk serve-ego`` runs it.

A scenario whose ego is ``{policy: external, params: {address: ADDRESS}}``
asks a process at ``ADDRESS`` for the ego's actions over ZeroMQ (the
protocol: ``docs/ego-protocol.md``). :func:`serve_reference_ego` is such a
process for the reference controller
(:class:`~avrisk.agents.external.server.AccController`), to try the protocol
and to compare an AV's own server with.
"""

from __future__ import annotations

from collections.abc import Callable

from avrisk.agents.external.params import DEFAULT_ADDRESS, is_loopback
from avrisk.api.errors import UserError
from avrisk.extras import needs_extra

__all__ = ["BindError", "NotLoopbackError", "serve_reference_ego"]


class NotLoopbackError(UserError):
    """An address beyond this machine, to bind without ``remote=True``."""


class BindError(UserError):
    """An address ZeroMQ cannot bind (malformed, in use, or a missing folder)."""


def serve_reference_ego(
    address: str = DEFAULT_ADDRESS,
    *,
    speed: float = 30.0,
    noise: float = 0.0,
    remote: bool = False,
    ready: Callable[[str], None] | None = None,
) -> None:
    """Serve the reference AV at ``address`` until interrupted.

    Parameters
    ----------
    address : str
        The ZeroMQ address to bind (``tcp://127.0.0.1:5555``,
        ``ipc:///tmp/av.sock``).
    speed : float, default=30.0
        The controller's wanted speed [m/s].
    noise : float, default=0.0
        Half-width of its uniform acceleration noise, seeded per rollout
        [m/s^2].
    remote : bool, default=False
        Allow an address beyond this machine (any host may then connect).
    ready : callable, optional
        Called with ``address`` once it is bound.

    Raises
    ------
    NotLoopbackError
        For an address beyond this machine without ``remote``, before binding.
    BindError
        If ZeroMQ cannot bind ``address``.
    avrisk.extras.MissingExtraError
        Without pyzmq and msgpack (the ``external`` extra).
    KeyboardInterrupt
        What ends the serving (the socket is closed first).
    """
    if not remote and not is_loopback(address):
        raise NotLoopbackError(
            f"{address} is not a loopback address; pass remote=True to bind it"
        )
    from avrisk.agents.external.server import AccController, EgoServer, serve

    with needs_extra("external", "the external ego"):
        import zmq
    bound = []

    def on_bound(where: str) -> None:
        bound.append(where)
        if ready is not None:
            ready(where)

    try:
        serve(
            EgoServer(AccController(speed=speed, noise=noise)), address, ready=on_bound
        )
    except zmq.ZMQError as exc:
        if bound:
            raise
        raise BindError(f"cannot bind {address}: {exc}") from None

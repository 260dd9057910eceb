"""``avrisk serve-ego``: the reference AV process for ``ego: {policy: external}``."""

from __future__ import annotations

from contextlib import suppress
from typing import Annotated

import typer

from avrisk.agents.external.params import DEFAULT_ADDRESS, is_loopback
from avrisk.cli.common import user_errors
from avrisk.extras import MissingExtraError


def serve_ego(
    address: Annotated[
        str, typer.Option(help="ZeroMQ address to bind (loopback unless --remote).")
    ] = DEFAULT_ADDRESS,
    speed: Annotated[float, typer.Option(help="Wanted speed [m/s].")] = 30.0,
    noise: Annotated[
        float,
        typer.Option(help="Uniform acceleration noise, seeded per rollout [m/s^2]."),
    ] = 0.0,
    remote: Annotated[
        bool, typer.Option("--remote", help="Allow binding beyond this machine.")
    ] = False,
) -> None:
    """Serve the reference AV (adaptive cruise control on lidar) over ZeroMQ.

    Binds ADDRESS and answers the external-ego protocol (docs/ego-protocol.md)
    until interrupted; test it with a scenario whose ego is
    {policy: external, params: {address: ADDRESS}}.
    """
    if not remote and not is_loopback(address):
        raise typer.BadParameter(f"{address} is not loopback; add --remote to allow")
    with user_errors(MissingExtraError):
        from avrisk.agents.external.server import AccController, EgoServer, serve

        server = EgoServer(AccController(speed=speed, noise=noise))
        with suppress(KeyboardInterrupt):
            serve(
                server, address, ready=lambda a: typer.echo(f"serving the ego at {a}")
            )

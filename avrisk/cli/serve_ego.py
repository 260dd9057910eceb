"""``avrisk serve-ego``: the reference AV process for ``ego: {policy: external}``."""

from __future__ import annotations

from contextlib import suppress
from typing import Annotated

import typer

from avrisk.agents.external.params import DEFAULT_ADDRESS
from avrisk.api.ego_server import NotLoopbackError, serve_reference_ego
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
    with user_errors(MissingExtraError), suppress(KeyboardInterrupt):
        try:
            serve_reference_ego(
                address,
                speed=speed,
                noise=noise,
                remote=remote,
                ready=lambda a: typer.echo(f"serving the ego at {a}"),
            )
        except NotLoopbackError:
            raise typer.BadParameter(
                f"{address} is not loopback; add --remote to allow"
            ) from None

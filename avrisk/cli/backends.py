"""``--workers``, ``--backend`` and ``--address``: where the rollouts are simulated.

The options of ``run`` and ``compare``; :mod:`avrisk.api.backends` opens
what they name.
"""

from __future__ import annotations

from typing import Annotated

import typer

from avrisk.api.backends import Backend

Workers = Annotated[
    int | None,
    typer.Option(
        min=1,
        help="Simulate in this many worker processes (one CPU each) [default: in "
        "this process; with --backend ray: the cluster's CPUs].",
    ),
]
BackendOption = Annotated[
    Backend,
    typer.Option(
        help="Where the workers run: local (this machine) or ray (a Ray cluster; "
        "pip install 'avrisk[ray]').",
    ),
]
Address = Annotated[
    str | None,
    typer.Option(
        help="Ray cluster to join, HOST:PORT or auto (with --backend ray) "
        "[default: start a local one].",
    ),
]

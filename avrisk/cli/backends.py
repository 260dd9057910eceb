"""``--workers``, ``--backend`` and ``--address``: where the rollouts are simulated.

The options of ``run``, ``compare`` and ``ab``; :mod:`avrisk.api.backends` opens
what they name, and registers the backends ``--backend`` offers.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

import typer

from avrisk.api.backends import backend_descriptions


def _described(descriptions: dict[str, str]) -> str:
    """``"local (this machine) or ray (a Ray cluster)"``: every backend, for help."""
    *rest, last = [f"{name} ({what})" for name, what in descriptions.items()]
    return f"{', '.join(rest)} or {last}" if rest else last


#: The backends registered when the command line is loaded: ``--backend``'s choices.
BackendName = StrEnum("BackendName", [(n, n) for n in backend_descriptions()])

Workers = Annotated[
    int | None,
    typer.Option(
        min=1,
        help="Simulate in this many worker processes (one CPU each) [default: in "
        "this process; with --backend ray: the cluster's CPUs].",
    ),
]
BackendOption = Annotated[
    BackendName,
    typer.Option(
        help=f"Where the workers run: {_described(backend_descriptions())}.",
    ),
]
Address = Annotated[
    str | None,
    typer.Option(
        help="Ray cluster to join, HOST:PORT or auto (with --backend ray) "
        "[default: start a local one].",
    ),
]

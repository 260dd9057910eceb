"""What every command shares: user-facing errors and warnings."""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape

#: Diagnostics and progress go to stderr; results to stdout. Both are at least
#: 120 columns wide so that tables and progress lines do not wrap or get cut
#: when piped to a file (Rich assumes 80 columns there).
_WIDTH = max(Console().width, 120)
err_console = Console(stderr=True, width=_WIDTH)
out_console = Console(width=_WIDTH)


class CliError(Exception):
    """A problem to report to the user in one sentence, without a traceback."""


def _show_warning(message: Any, category: type[Warning], *args: Any, **kw: Any) -> None:
    err_console.print(
        f"[yellow]warning:[/] {escape(str(message))}", highlight=False, soft_wrap=True
    )


@contextmanager
def user_errors(*expected: type[Exception]) -> Iterator[None]:
    """Turn expected failures into a red one-line message and exit code 2.

    Warnings raised meanwhile (an estimate with zero or few effective hits) are
    printed as one yellow line each instead of Python's source-line format.
    """
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            yield
    except (CliError, *expected) as exc:
        err_console.print(
            f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True
        )
        raise typer.Exit(code=2) from None


def resolve_device(name: str) -> str:
    """The torch device a ``--device`` value names, checked to be usable here.

    Parameters
    ----------
    name : str
        ``auto`` (``cuda`` when ``torch.cuda.is_available()``, else ``cpu``),
        or a torch device such as ``cpu``, ``cuda`` or ``cuda:1``.

    Returns
    -------
    str
        The device, e.g. ``"cpu"``.

    Raises
    ------
    CliError
        For a name torch does not know or a device this machine lacks.
    """
    import torch

    if name.strip().lower() == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    try:
        device = torch.device(name)
    except (RuntimeError, ValueError):
        raise CliError(
            f"--device {name!r} is not a torch device; use auto, cpu or cuda"
        ) from None
    try:
        torch.empty(0, device=device)
    except (RuntimeError, AssertionError, AttributeError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else "unusable"
        raise CliError(
            f"--device {name}: not available on this machine ({reason}); use "
            "--device cpu or --device auto"
        ) from None
    return str(device)


def _device_option(name: str) -> str:
    """``--device`` callback: the resolved device, or one red line and exit 2."""
    with user_errors():
        return resolve_device(name)


#: The ``--device`` option of the commands that simulate.
Device = Annotated[
    str,
    typer.Option(
        callback=_device_option,
        help="Torch device of the simulator: auto (cuda when available), cpu, "
        "cuda or cuda:N.",
    ),
]

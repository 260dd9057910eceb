"""What every command shares: consoles, user-facing errors, warnings, Ctrl-C."""

from __future__ import annotations

import errno
import shlex
import tempfile
import textwrap
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape

from avrisk.api.errors import UserError
from avrisk.cli.interrupt import INTERRUPTED
from avrisk.rare.final_stage import UnreliableEstimateWarning, ZeroHitsWarning

#: Diagnostics and progress go to stderr; results to stdout (so that a
#: command's ``--json`` output parses). Each is as wide as its terminal, or
#: ``$COLUMNS`` (80 when unset) when piped: the tables fit 80 columns.
err_console = Console(stderr=True)
out_console = Console()


class CliError(UserError):
    """A problem with the command line, reported in one sentence (no traceback)."""


#: Warnings of an estimate's own diagnostics, raised at each run's main
#: threshold (the others' are in the results' trust column): the first of each
#: kind is printed, those of a comparison's other runs are in the table too.
ONCE_PER_COMMAND = (UnreliableEstimateWarning, ZeroHitsWarning)


class _WarningPrinter:
    """``warnings.showwarning`` as yellow lines, wrapped at the console's width.

    Each warning is wrapped at spaces, never inside a word (a path).
    """

    def __init__(self) -> None:
        self.shown: set[type[Warning]] = set()

    def __call__(
        self, message: Any, category: type[Warning], *args: Any, **kw: Any
    ) -> None:
        if issubclass(category, ONCE_PER_COMMAND):
            if category in self.shown:
                return
            self.shown.add(category)
        # Wrapped at spaces only: a path in the message stays whole.
        lines = textwrap.fill(
            f"warning: {message}",
            err_console.width,
            break_long_words=False,
            break_on_hyphens=False,
        ).removeprefix("warning:")
        err_console.print(
            f"[yellow]warning:[/]{escape(lines)}", highlight=False, soft_wrap=True
        )


@contextmanager
def user_errors(*expected: type[Exception]) -> Iterator[None]:
    """Turn expected failures into a red one-line message and exit code 2.

    Warnings raised meanwhile are printed as yellow lines instead of Python's
    source-line format; of an estimate's diagnostics at its main threshold
    (zero or few effective hits, a heavy tail), only the first of each kind
    (the results give each threshold's trust).
    """
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _WarningPrinter()
            yield
    except (UserError, *expected) as exc:
        err_console.print(
            f"[bold red]error:[/] {escape(_clipped(str(exc)))}",
            highlight=False,
            soft_wrap=True,
        )
        raise typer.Exit(code=2) from None


def command_line(ctx: typer.Context) -> str:
    """The command being run, as one could type it again.

    Rebuilt from the parameters given on the command line (arguments first,
    then options in their order of declaration, each with its value as
    parsed); defaults are left out, so the command means the same after a
    change of a default only if it named every value.

    Examples
    --------
    ``avrisk run highway_idm --out runs/x --n-final 2000``
    """
    arguments, options = [], []
    for param in ctx.command.params:
        name = param.name
        source = ctx.get_parameter_source(name) if name else None
        if source is None or source.name != "COMMANDLINE":
            continue
        value = ctx.params[name]
        if param.param_type_name == "argument":
            arguments.append(str(value))
        elif getattr(param, "is_flag", False):
            options.append(param.opts[0] if value else param.secondary_opts[0])
        else:
            for item in value if param.multiple else [value]:
                options += [param.opts[0], str(item)]
    return shlex.join(["avrisk", ctx.info_name or "", *arguments, *options])


@contextmanager
def resumable(ctx: typer.Context) -> Iterator[None]:
    """Ctrl-C: one line saying how to resume, and exit status 130, no traceback.

    For commands whose work is recorded as it goes (``run``, ``compare``):
    rerunning the same command resumes it.
    """
    try:
        yield
    except KeyboardInterrupt:
        err_console.print(
            "interrupted; what was simulated is recorded. Resume with: "
            f"{escape(command_line(ctx))}",
            highlight=False,
            soft_wrap=True,
        )
        raise typer.Exit(code=INTERRUPTED) from None


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


#: Longest line of an error message printed; a longer one (a huge value echoed
#: back) is cut, saying by how much.
MAX_MESSAGE_LINE = 500


def _clipped(message: str) -> str:
    return "\n".join(
        line
        if len(line) <= MAX_MESSAGE_LINE
        else f"{line[:MAX_MESSAGE_LINE]}... ({len(line) - MAX_MESSAGE_LINE:,} "
        "more characters)"
        for line in message.splitlines()
    )


def check_output_folder(path: Path, flag: str = "--out") -> None:
    """Refuse, before any work, a folder to write in that cannot be written.

    ``path`` (a run directory, made if missing) must not be a file nor lie
    under one, and its nearest existing folder must take a scratch file (a
    read-only file system or a folder without write permission does not).

    Raises
    ------
    CliError
    """
    if path.exists() and not path.is_dir():
        raise CliError(f"{flag} {path}: is a file; give a folder (new or a run's)")
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise CliError(
            f"{flag} {path}: {existing} is a file, so no folder can be made there"
        )
    made = "cannot write in" if existing == path else "cannot create that folder in"
    _check_writable(existing, f"{flag} {path}: {made} {existing}")


def check_output_file(path: Path, flag: str = "--out") -> None:
    """Refuse, before any work, a file to write that cannot be written.

    Raises
    ------
    CliError
        If ``path`` is a folder, its folder does not exist (or is a file) or
        cannot be written in.
    """
    if path.is_dir():
        raise CliError(f"{flag} {path}: is a folder; give a file name")
    if not path.parent.is_dir():
        raise CliError(
            f"{flag} {path}: folder {path.parent} does not exist; create it first"
        )
    _check_writable(path.parent, f"{flag} {path}: cannot write in {path.parent}")


def _check_writable(folder: Path, problem: str) -> None:
    """Write a scratch file in ``folder``: the only sure test (root, read-only FS).

    ``problem`` starts the error's line; the reason follows. A folder that
    exists but answers "No such file or directory" (``/proc``) takes no new
    files: said so, not that.
    """
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        reason = (
            "it takes no new files"
            if exc.errno == errno.ENOENT
            else exc.strerror or str(exc)
        )
        raise CliError(f"{problem}: {reason}") from None

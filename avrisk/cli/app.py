"""The ``avrisk`` Typer application: every command, registered in one place.

Command modules define plain functions and know nothing of this application.
A command's module is imported only when that command runs or shows its own
help (most import torch, which takes seconds): ``avrisk --help`` lists the
commands from their docstrings, read from the source.
"""

from __future__ import annotations

import ast
import importlib.util
from importlib import import_module
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import typer
from typer.core import TyperCommand, TyperGroup
from typer.main import get_command_from_info
from typer.models import CommandInfo

from avrisk.cli.interrupt import loading
from avrisk.tensors.allocator import keep_freed_memory

if TYPE_CHECKING:  # Typer's own click: a dependency of it, or vendored in it
    import click

#: The commands in the order ``--help`` lists them, each as (module, function);
#: ``scenarios`` follows (a group of its own).
COMMANDS = {
    "run": ("avrisk.cli.run", "run"),
    "compare": ("avrisk.cli.run", "compare"),
    "report": ("avrisk.cli.run", "report"),
    "ab": ("avrisk.cli.ab", "ab"),
    "simulate": ("avrisk.cli.simulate", "simulate"),
    "replay": ("avrisk.cli.simulate", "replay"),
    "demo": ("avrisk.cli.demo", "demo"),
    "train-drivers": ("avrisk.cli.train_drivers", "train_drivers_command"),
    "train-vision": ("avrisk.cli.train_vision", "train_vision_command"),
    "serve-ego": ("avrisk.cli.serve_ego", "serve_ego"),
    "realism": ("avrisk.cli.realism", "realism_command"),
}


def docstring(module: str, function: str) -> str:
    """The docstring of ``module.function``, read from the source, not imported."""
    spec = importlib.util.find_spec(module)
    assert spec is not None and spec.origin is not None, module
    for node in ast.parse(Path(spec.origin).read_text()).body:
        if isinstance(node, ast.FunctionDef) and node.name == function:
            return ast.get_docstring(node) or ""
    raise LookupError(f"{module} has no function {function}")


class ParsedWhileLoading:
    """A command (or group) whose arguments are parsed as part of loading it.

    Typer's parsing imports and builds more on first use (pydantic's type
    adapters), for a few tenths of a second: a Ctrl-C then is one line
    (:func:`~avrisk.cli.interrupt.loading`), where Typer would exit in silence.
    """

    def make_context(  # noqa: D102
        self, info_name: str | None, args: list[str], *rest: Any, **extra: Any
    ) -> click.Context:
        with loading():
            return super().make_context(info_name, args, *rest, **extra)  # type: ignore[misc]


class LoadingCommand(ParsedWhileLoading, TyperCommand):
    """A command of :class:`LazyGroup`, parsed while loading."""


class LazyGroup(ParsedWhileLoading, TyperGroup):
    """A group whose :attr:`lazy` commands are each imported when used.

    Listing them (``--help``) builds a stand-in of each from its docstring;
    running one, or its ``--help``, imports its module.
    """

    #: Command name -> (module, function), listed before any other command.
    lazy: ClassVar[dict[str, tuple[str, str]]] = COMMANDS
    _listing = False

    def list_commands(self, ctx: click.Context) -> list[str]:  # noqa: D102
        return [*self.lazy, *super().list_commands(ctx)]

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        """The command ``name``: a stand-in while listing, else the command itself."""
        if name not in self.lazy:
            return super().get_command(ctx, name)
        module, function = self.lazy[name]
        if self._listing:
            return TyperCommand(name, help=docstring(module, function))
        with loading():  # the command's module, and Typer's reading of it
            callback = getattr(import_module(module), function)
            return get_command_from_info(
                CommandInfo(name=name, callback=callback, cls=LoadingCommand),
                pretty_exceptions_short=app.pretty_exceptions_short,
                rich_markup_mode=self.rich_markup_mode,
            )

    def format_commands(  # noqa: D102
        self, ctx: click.Context, formatter: click.HelpFormatter
    ) -> None:
        self._listing = True
        try:
            super().format_commands(ctx, formatter)
        finally:
            self._listing = False


app = typer.Typer(
    name="avrisk",
    cls=LazyGroup,
    help="Rare-event risk estimation for autonomous-vehicle policies.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
    # Plain help text: units such as "[s]" must not be read as Rich markup.
    rich_markup_mode=None,
)


def _print_version(value: bool) -> None:
    if value:
        import avrisk

        typer.echo(f"avrisk {avrisk.__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False,
        "--version",
        callback=_print_version,
        is_eager=True,
        help="Print the version.",
    ),
) -> None:
    """Rare-event risk estimation for autonomous-vehicle policies."""
    keep_freed_memory()


class _ScenarioCommands(LazyGroup):
    lazy: ClassVar[dict[str, tuple[str, str]]] = {
        "show": ("avrisk.cli.scenarios", "show_scenario")
    }


scenarios = typer.Typer(
    cls=_ScenarioCommands,
    help="The bundled scenarios: list them (no command), or show one.",
    invoke_without_command=True,
    rich_markup_mode=None,
)


@scenarios.callback()
def _scenarios(ctx: typer.Context) -> None:
    """List the bundled scenarios with their descriptions; 'show NAME' prints one."""
    if ctx.invoked_subcommand is None:
        from avrisk.cli.scenarios import list_scenarios

        list_scenarios()


app.add_typer(scenarios, name="scenarios")

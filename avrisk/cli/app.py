"""The ``avrisk`` Typer application: every command, registered in one place.

Command modules define plain functions and know nothing of this application.
"""

import typer

from avrisk.cli.demo import demo
from avrisk.cli.realism import realism_command
from avrisk.cli.run import compare, report, run
from avrisk.cli.scenarios import list_scenarios, show_scenario
from avrisk.cli.serve_ego import serve_ego
from avrisk.cli.simulate import replay, simulate
from avrisk.cli.train_drivers import train_drivers_command
from avrisk.cli.train_vision import train_vision_command
from avrisk.tensors.allocator import keep_freed_memory

app = typer.Typer(
    name="avrisk",
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


for command in (run, compare, report, simulate, replay, demo):
    app.command()(command)
app.command("train-drivers")(train_drivers_command)
app.command("train-vision")(train_vision_command)
app.command("serve-ego")(serve_ego)
app.command("realism")(realism_command)

scenarios = typer.Typer(
    help="The bundled scenarios: list them (no command), or show one.",
    invoke_without_command=True,
    rich_markup_mode=None,
)


@scenarios.callback()
def _scenarios(ctx: typer.Context) -> None:
    """List the bundled scenarios with their descriptions; 'show NAME' prints one."""
    if ctx.invoked_subcommand is None:
        list_scenarios()


scenarios.command("show")(show_scenario)
app.add_typer(scenarios, name="scenarios")

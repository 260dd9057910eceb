"""``avrisk scenarios``: the bundled scenarios, listed or written out as a start.

The bundled scenarios are YAML files inside the package
(``avrisk/data/scenarios/``); ``avrisk run NAME`` takes them by name.
``avrisk scenarios`` lists them, a line of facts each and its description
below; ``avrisk scenarios show NAME`` prints one (comments included) and
``--write FILE`` writes it as a starting file to edit, never over an existing
file unless ``--force``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.padding import Padding

from avrisk.api.scenarios import bundled, scenario_yaml
from avrisk.cli.common import (
    CliError,
    check_output_file,
    err_console,
    out_console,
    user_errors,
)
from avrisk.scenario import ScenarioSpecError


def list_scenarios() -> None:
    """List the bundled scenarios: a line of facts each, its description below.

    The description wraps at the console's width, indented under its name.
    """
    with user_errors(ScenarioSpecError):
        scenarios = bundled()
    width = max(map(len, scenarios.specs))
    for name, spec in scenarios.specs.items():
        out_console.print(
            f"[bold]{escape(f'{name:{width}}')}[/]  {spec.n_vehicles} vehicles, "
            f"{spec.simulation.horizon:g} s, ego {escape(spec.ego.policy)}",
            highlight=False,
        )
        out_console.print(
            Padding(escape(" ".join((spec.description or "").split())), (0, 0, 1, 4)),
            highlight=False,
        )
    # The folder on a line of its own, whole (to copy), however long.
    err_console.print(
        f"bundled in {escape(str(scenarios.folder))}", highlight=False, soft_wrap=True
    )
    err_console.print(
        "start your own with: avrisk scenarios show NAME --write my_scenario.yaml",
        highlight=False,
    )


def show_scenario(
    name: Annotated[str, typer.Argument(help="A bundled scenario's name.")],
    write: Annotated[
        Path | None,
        typer.Option(
            "--write",
            help="Write it to this YAML file (a starting point to edit) instead of "
            "printing it.",
        ),
    ] = None,
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite --write FILE if it exists.")
    ] = False,
) -> None:
    """Print a bundled scenario's YAML, or write it out as a starting file."""
    with user_errors(ScenarioSpecError):
        if write is not None:
            check_output_file(write, "--write")
            if write.exists() and not force:
                raise CliError(
                    f"--write {write}: exists already; give --force to overwrite it"
                )
        try:
            text = scenario_yaml(name, write)
        except OSError as exc:
            raise CliError(f"--write {write}: cannot write: {exc.strerror}") from None
        if write is None:
            typer.echo(text, nl=False)
            return
    err_console.print(
        f"wrote {escape(str(write))} (bundled scenario {name}); edit it, then: "
        f"avrisk run {escape(str(write))} --out runs/{name}",
        highlight=False,
        soft_wrap=True,
    )

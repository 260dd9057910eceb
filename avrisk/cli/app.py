"""The Typer application that every sub-command module registers itself on."""

import typer

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


def main() -> None:
    """Entry point of the ``avrisk`` console script."""
    # Sub-command modules register on `app` when imported.
    import avrisk.cli.demo  # noqa: F401
    import avrisk.cli.run  # noqa: F401
    import avrisk.cli.simulate  # noqa: F401
    import avrisk.cli.train_drivers  # noqa: F401

    app()

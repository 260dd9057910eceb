"""The ``avrisk`` command line (Typer). Each sub-command lives in its own module."""

from avrisk.cli.app import app, main

__all__ = ["app", "main"]

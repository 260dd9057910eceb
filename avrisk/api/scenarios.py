"""The bundled scenarios, as ``avrisk scenarios`` lists and shows them.

A bundled scenario is a YAML file shipped in the package
(:func:`avrisk.scenario.bundled_folder`); :func:`bundled` reads them all,
:func:`scenario_yaml` gives one's text and writes it out as a user's starting
file.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

if TYPE_CHECKING:
    from avrisk.scenario import ScenarioSpec

__all__ = ["BundledScenarios", "bundled", "scenario_yaml"]


class BundledScenarios(NamedTuple):
    """The scenarios shipped with avrisk.

    Attributes
    ----------
    specs : dict of str to ScenarioSpec
        Each bundled scenario by name, in name order.
    folder : pathlib.Path
        The folder they ship in (a copy is a starting point to edit).
    """

    specs: dict[str, ScenarioSpec]
    folder: Path


def bundled() -> BundledScenarios:
    """Every bundled scenario, read and checked, and their folder.

    Raises
    ------
    avrisk.scenario.ScenarioSpecError
        If a bundled file does not load (a damaged installation).
    """
    from avrisk.scenario import bundled_folder, bundled_scenarios, load_spec

    specs = {name: load_spec(name) for name in bundled_scenarios()}
    return BundledScenarios(specs, bundled_folder())


def scenario_yaml(name: str, write: Path | None = None) -> str:
    """A bundled scenario's YAML text, also written to ``write`` when given.

    The file is written whole or not at all (a temporary file renamed over
    it); whether it may replace one is the caller's to decide.

    Raises
    ------
    avrisk.scenario.ScenarioSpecError
        If ``name`` is no bundled scenario (the message lists them).
    OSError
        If ``write`` cannot be written.
    """
    from avrisk.pipeline.files import write_atomic
    from avrisk.scenario import bundled_scenario_text

    text = bundled_scenario_text(name)
    if write is not None:
        write_atomic(write, text)
    return text

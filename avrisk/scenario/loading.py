"""Reading a scenario: a YAML file or a bundled name to a validated spec.

Files are parsed with ``yaml.safe_load`` (no Python objects are built) and are
refused above :data:`MAX_SPEC_BYTES`.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from avrisk.scenario.errors import ScenarioSpecError, format_validation_error
from avrisk.scenario.spec import SCENARIO_NAME, ScenarioSpec

#: Largest scenario file accepted [bytes]. Real specs are a few kB.
MAX_SPEC_BYTES = 1 << 20

_BUNDLED_PACKAGE = "avrisk"
_BUNDLED_DIR = ("data", "scenarios")


def bundled_scenarios() -> list[str]:
    """Names of the scenarios shipped with avrisk (usable by name in the CLI).

    Returns
    -------
    list of str
        Sorted names, e.g. ``["highway_default"]``.
    """
    folder = resources.files(_BUNDLED_PACKAGE).joinpath(*_BUNDLED_DIR)
    return sorted(
        p.name.removesuffix(".yaml")
        for p in folder.iterdir()
        if p.name.endswith(".yaml")
    )


def load_spec(path_or_name: str | Path) -> ScenarioSpec:
    """Read and validate a scenario from a YAML file or a bundled name.

    Parameters
    ----------
    path_or_name : str or pathlib.Path
        A path to a ``.yaml`` file, or the name of a bundled scenario (see
        :func:`bundled_scenarios`), e.g. ``"highway_default"``.

    Returns
    -------
    ScenarioSpec

    Raises
    ------
    ScenarioSpecError
        If the file does not exist, is larger than ``MAX_SPEC_BYTES``, is not
        YAML, or does not validate; the message names each bad field.

    Examples
    --------
    >>> spec = load_spec("highway_default")
    >>> spec.road.n_lanes, spec.n_vehicles
    (6, 6)
    """
    text, source = _read_source(path_or_name)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ScenarioSpecError(f"{source}: not valid YAML: {exc}") from None
    return spec_from_dict(data, source=source)


def spec_from_dict(data: Any, *, source: str = "<dict>") -> ScenarioSpec:
    """Validate an already-parsed mapping into a :class:`ScenarioSpec`.

    Parameters
    ----------
    data : mapping
        The parsed YAML document.
    source : str, default="<dict>"
        Where the data came from, for error messages.

    Returns
    -------
    ScenarioSpec

    Raises
    ------
    ScenarioSpecError
        If the mapping does not validate.
    """
    if not isinstance(data, Mapping):
        raise ScenarioSpecError(
            f"{source}: the top level must be a mapping of fields (road, "
            f"vehicles, ...); got {type(data).__name__}"
        )
    try:
        return ScenarioSpec.model_validate(dict(data))
    except ValidationError as exc:
        raise ScenarioSpecError(format_validation_error(exc, source)) from None


def _read_source(path_or_name: str | Path) -> tuple[str, str]:
    """Return the text of a spec file or bundled scenario and its display name."""
    path = Path(path_or_name)
    if path.is_file():
        size = path.stat().st_size
        if size > MAX_SPEC_BYTES:
            raise ScenarioSpecError(
                f"{path}: {size} bytes is larger than the {MAX_SPEC_BYTES}-byte "
                "limit for a scenario file; is this the right file?"
            )
        try:
            return path.read_text(encoding="utf-8"), str(path)
        except (OSError, UnicodeDecodeError) as exc:
            raise ScenarioSpecError(f"{path}: cannot be read: {exc}") from None
    name = str(path_or_name)
    if SCENARIO_NAME.match(name) and name in bundled_scenarios():
        res = resources.files(_BUNDLED_PACKAGE).joinpath(*_BUNDLED_DIR, name + ".yaml")
        return res.read_text(encoding="utf-8"), f"{name} (bundled)"
    raise ScenarioSpecError(
        f"no scenario file {str(path_or_name)!r} and no bundled scenario of that "
        f"name; give a path to a .yaml file or one of {bundled_scenarios()}"
    )

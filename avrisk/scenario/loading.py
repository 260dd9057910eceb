"""Reading a scenario: a YAML file or a bundled name to a validated spec.

Files are parsed with a safe loader (no Python objects are built) that also
refuses what ``yaml.safe_load`` lets through silently: a key given twice in one
mapping (the last would win), nesting deeper than :data:`MAX_DEPTH` and
anchors and aliases that expand to more than :data:`MAX_NODES` values. Files
are refused above :data:`MAX_SPEC_BYTES`.
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from avrisk.scenario.errors import ScenarioSpecError, clip, format_validation_error
from avrisk.scenario.spec import SCENARIO_NAME, ScenarioSpec

#: Largest scenario file accepted [bytes]. Real specs are a few kB.
MAX_SPEC_BYTES = 1 << 20
#: Deepest nesting of mappings and lists accepted. A scenario needs about 5.
MAX_DEPTH = 32
#: Most values (with aliases expanded) accepted. Real specs have a few hundred.
MAX_NODES = 100_000

_BUNDLED_PACKAGE = "avrisk"
_BUNDLED_DIR = ("data", "scenarios")


def bundled_folder() -> Traversable:
    """The folder of the bundled scenario files: ``avrisk/data/scenarios``."""
    return resources.files(_BUNDLED_PACKAGE).joinpath(*_BUNDLED_DIR)


def bundled_scenarios() -> list[str]:
    """Names of the scenarios shipped with avrisk (usable by name in the CLI).

    Returns
    -------
    list of str
        Sorted names, e.g. ``["highway_default"]``.
    """
    return sorted(
        p.name.removesuffix(".yaml")
        for p in bundled_folder().iterdir()
        if p.name.endswith(".yaml")
    )


def bundled_scenario_text(name: str) -> str:
    """The YAML text of a bundled scenario, comments included (a starting file).

    Raises
    ------
    ScenarioSpecError
        If no bundled scenario has that name (the message lists them).
    """
    if not (SCENARIO_NAME.match(name) and name in bundled_scenarios()):
        raise ScenarioSpecError(
            f"no bundled scenario {clip(name, 80)!r}; the bundled ones are "
            f"{', '.join(bundled_scenarios())}"
        )
    return bundled_folder().joinpath(name + ".yaml").read_text(encoding="utf-8")


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
        data = _parse(text)
    except _RefusedYAML as exc:
        raise ScenarioSpecError(f"{source}: {exc}") from None
    except yaml.YAMLError as exc:
        raise ScenarioSpecError(f"{source}: not valid YAML: {exc}") from None
    return spec_from_dict(data, source=source)


class _RefusedYAML(yaml.YAMLError):
    """Valid YAML that a scenario file may not be (the message says why)."""


class _SpecLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses duplicate keys, deep nesting, huge aliases."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        # Per composed node: values it holds with aliases expanded, nesting depth.
        self._extent: dict[int, tuple[int, int]] = {}

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self._depth >= MAX_DEPTH:
            mark = self.peek_event().start_mark
            raise _RefusedYAML(
                f"line {mark.line + 1}: nested deeper than {MAX_DEPTH} levels "
                "(a scenario needs about 5); is this the right file?"
            )
        self._depth += 1
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if id(node) not in self._extent:  # not an alias of a node seen before
            children = _children(node)
            extents = [self._extent[id(c)] for c in children]
            size = 1 + sum(e[0] for e in extents)
            depth = 1 + max((e[1] for e in extents), default=0)
            if size > MAX_NODES or depth > MAX_DEPTH:
                what = (
                    f"more than {MAX_NODES:,} values"
                    if size > MAX_NODES
                    else f"nesting deeper than {MAX_DEPTH} levels"
                )
                raise _RefusedYAML(
                    f"line {node.start_mark.line + 1}: its anchors and aliases "
                    f"expand to {what}; is this the right file?"
                )
            self._extent[id(node)] = (size, depth)
        return node

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            first: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # '<<' merges keys that the mapping may override
                key = self.construct_object(key_node, deep=True)
                line = key_node.start_mark.line + 1
                try:
                    seen = first.get(key)
                except TypeError:  # an unhashable key: refused by validation
                    continue
                if seen is not None:
                    raise _RefusedYAML(
                        f"line {line}: duplicate key {_short(key)} (first given "
                        f"at line {seen}); YAML would silently keep the last, so "
                        "remove or merge one"
                    )
                first[key] = line
        return super().construct_mapping(node, deep=deep)


def _construct_int(loader: yaml.SafeLoader, node: Any) -> Any:
    """YAML's int, refusing one too long to convert (Python's digit limit)."""
    try:
        return yaml.SafeLoader.construct_yaml_int(loader, node)
    except ValueError:
        raise _RefusedYAML(
            f"line {node.start_mark.line + 1}: an integer of {len(node.value):,} "
            "characters; is this the right file?"
        ) from None


_SpecLoader.add_constructor("tag:yaml.org,2002:int", _construct_int)


def _children(node: Any) -> list[Any]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 5]}...'"


def _parse(text: str) -> Any:
    """The YAML document in ``text``, refused as :class:`_RefusedYAML` if hostile."""
    loader = _SpecLoader(text)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


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
        return bundled_scenario_text(name), f"{name} (bundled)"
    raise ScenarioSpecError(
        f"no scenario file {str(path_or_name)!r} and no bundled scenario of that "
        f"name; give a path to a .yaml file or one of {bundled_scenarios()}"
    )

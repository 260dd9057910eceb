"""Bundled scenarios written out with a shorter horizon, for fast CLI tests."""

from importlib import resources
from pathlib import Path

import yaml


def shortened_scenario(
    directory: Path,
    horizon: float,
    *,
    file: str = "short.yaml",
    scenario: str = "highway_idm",
    **sections,
) -> Path:
    """Write ``scenario``'s YAML cut to ``horizon`` seconds into ``directory/file``.

    ``sections`` replace top-level entries (``name``, ``ego``, ...) whole.
    """
    text = resources.files("avrisk.data.scenarios").joinpath(f"{scenario}.yaml")
    spec = yaml.safe_load(text.read_text())
    spec["simulation"]["horizon"] = horizon
    spec.update(sections)
    path = directory / file
    path.write_text(yaml.safe_dump(spec))
    return path

"""The import rules of DESIGN.md, checked on the source (no imports executed)."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "avrisk"

# subpackage -> avrisk subpackages it must never import
FORBIDDEN = {
    "rare": {
        "sim",
        "safety",
        "scenario",
        "agents",
        "pipeline",
        "distributed",
        "report",
        "cli",
        "learning",
        "testing",
    },
    "sim": {"rare", "pipeline", "distributed", "report", "cli", "learning"},
    "safety": {"rare", "pipeline", "distributed", "report", "cli", "learning"},
    "agents": {"rare", "pipeline", "distributed", "report", "cli", "learning"},
    "scenario": {"pipeline", "distributed", "report", "cli", "learning"},
}


def avrisk_imports(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module]
        for name in names:
            parts = name.split(".")
            if parts[0] == "avrisk" and len(parts) > 1:
                yield parts[1]


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_layer_imports_nothing_it_must_not_know_about(layer):
    offenders = []
    for path in (PACKAGE / layer).rglob("*.py"):
        offenders += [
            f"{path.relative_to(PACKAGE)} imports avrisk.{sub}"
            for sub in avrisk_imports(path)
            if sub in FORBIDDEN[layer]
        ]
    assert not offenders, offenders


def test_the_estimation_engine_exists_as_its_own_layer():
    assert (PACKAGE / "rare" / "cross_entropy.py").is_file()

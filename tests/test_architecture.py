"""The import rules of docs/design.md, checked on the source (no imports executed).

Every import statement counts, wherever it stands (top level, inside a
function, under ``TYPE_CHECKING``): a deferred import is still a dependency.
"""

import ast
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "avrisk"


def _load_import_graph():
    spec = importlib.util.spec_from_file_location(
        "import_graph", ROOT / "scripts" / "import_graph.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


import_graph = _load_import_graph()

# subpackage -> the only avrisk subpackages (or top-level modules) it may import
ALLOWED = {
    "tensors": set(),
    "rare": {"registry", "extras"},
    "sim": {"tensors", "registry"},
    "agents": {"sim", "tensors", "registry", "extras"},
    "safety": {"sim", "tensors", "registry"},
    # the camera renderer implements the simulator's camera seam
    "render": {"sim", "tensors"},
    "scenario": {"rare", "registry"},
    "assembly": {
        "sim",
        "render",
        "agents",
        "safety",
        "scenario",
        "tensors",
        "rare",
        "registry",
        "fingerprint",
    },
    # the run driver serves any black box: it knows nothing of the simulator
    "pipeline": {"rare", "registry", "fingerprint"},
    "report": {"pipeline", "rare", "assembly", "scenario"},
    # the scenario-level calls the command line is a shell over
    "api": {
        "pipeline",
        "rare",
        "assembly",
        "scenario",
        "report",
        "registry",
        "extras",
    },
    "testing": {"rare"},
    # the Gymnasium environment: a scenario built and stepped by hand
    "gym": {"assembly", "agents", "scenario", "sim", "extras"},
    # the realism report: learned drivers against held-out human data, in the
    # simulator; no estimator (the scenario layer gives it the xi prior)
    "realism": {
        "learning",
        "agents",
        "sim",
        "safety",
        "scenario",
        "pipeline",
        "fingerprint",
    },
}


def _imports(layer):
    for path in sorted((PACKAGE / layer).rglob("*.py")):
        for sub in import_graph.imported_subpackages(path):
            if sub != layer:
                yield path.relative_to(PACKAGE), sub


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_layer_imports_only_what_it_may_know_about(layer):
    assert (PACKAGE / layer).is_dir()
    offenders = [
        f"{path} imports avrisk.{sub}"
        for path, sub in _imports(layer)
        if sub not in ALLOWED[layer]
    ]
    assert not offenders, offenders


def test_no_two_subpackages_import_each_other_even_through_others():
    edges = import_graph.subpackage_edges(PACKAGE)
    assert ("agents", "sim") in edges  # the graph is read at all
    found = import_graph.cycles(edges)
    assert not found, "import cycles: " + "; ".join(" -> ".join(c) for c in found)


def test_the_cycle_finder_reports_a_cycle_through_three_subpackages():
    edges = {("a", "b"): 1, ("b", "c"): 2, ("c", "a"): 1, ("c", "d"): 1}
    assert import_graph.cycles(edges) == [["a", "b", "c", "a"]]
    assert import_graph.cycles({("a", "b"): 1, ("b", "c"): 1}) == []


def test_no_module_loads_names_lazily():
    # A module-level __getattr__ would hide an import cycle behind lazy loading.
    lazy = [
        str(path.relative_to(PACKAGE))
        for path in PACKAGE.rglob("*.py")
        for node in ast.parse(path.read_text()).body
        if isinstance(node, ast.FunctionDef) and node.name == "__getattr__"
    ]
    assert not lazy, lazy


def test_the_estimation_engine_exists_as_its_own_layer():
    assert (PACKAGE / "rare" / "cross_entropy.py").is_file()

"""The import rules of docs/design.md and the size limits, checked on the source.

No import is executed. Every import statement counts, wherever it stands (top
level, inside a function, under ``TYPE_CHECKING``): a deferred import is still
a dependency. Modules stay under about 500 lines (a longer one says why at its
top) and functions under about 60 lines of code (``scripts/code_shape.py``
lists them); the modules of ``rare/`` not yet split along their seams are
named below with their reasons, and each entry must still be
needed, so the lists only shrink.
"""

import ast
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "avrisk"


def _load_script(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


import_graph = _load_script("import_graph")
code_shape = _load_script("code_shape")

#: How a module over :data:`MODULE_LINES` lines states, in its docstring, why
#: it is one module.
LONG_MODULE_REASON = "Why one module:"
MODULE_LINES = code_shape.MODULE_LINES
FUNCTION_CODE_LINES = code_shape.FUNCTION_CODE_LINES

#: Modules over MODULE_LINES lines not yet split (issue 43, step 4), and why.
MODULES_NOT_YET_SPLIT: dict[str, str] = {}

#: Functions over FUNCTION_CODE_LINES lines of code not yet split, and why.
FUNCTIONS_NOT_YET_SPLIT: dict[str, str] = {}

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
    "pipeline": {"rare", "registry", "fingerprint", "version"},
    "report": {"pipeline", "rare", "assembly", "scenario"},
    # the scenario-level calls the command line is a shell over, and the
    # calls of its other commands: training (learning), the reference AV's
    # server (agents), the realism report, the demo's exact problems (testing)
    "api": {
        "pipeline",
        "rare",
        "assembly",
        "scenario",
        "report",
        "registry",
        "extras",
        "version",
        "agents",
        "learning",
        "realism",
        "testing",
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


def test_no_two_modules_import_each_other_even_through_others():
    edges = import_graph.module_edges(PACKAGE)
    assert ("avrisk.sim.simulator", "avrisk.sim.road") in edges  # read at all
    found = import_graph.cycles(edges)
    assert not found, "import cycles: " + "; ".join(" -> ".join(c) for c in found)


def test_the_module_graph_resolves_submodules_relative_imports_and_packages(
    tmp_path,
):
    package = tmp_path / "pkg"
    (package / "sub").mkdir(parents=True)
    (package / "__init__.py").write_text("from pkg.sub import leaf\n")
    (package / "sub" / "__init__.py").write_text("from .leaf import X\n")
    (package / "sub" / "leaf.py").write_text("import numpy\nX = 1\n")
    (package / "top.py").write_text("from pkg.sub.leaf import X\nimport pkg\n")
    assert dict(import_graph.module_edges(package)) == {
        ("pkg", "pkg.sub.leaf"): 1,
        ("pkg.sub", "pkg.sub.leaf"): 1,
        ("pkg.top", "pkg.sub.leaf"): 1,
        ("pkg.top", "pkg"): 1,
    }


def _module_paths():
    return sorted(PACKAGE.rglob("*.py"))


def _name(path):
    return str(path.relative_to(ROOT))


def _docstring(path):
    return ast.get_docstring(ast.parse(path.read_text())) or ""


def test_no_module_is_long_without_a_reason_at_its_top():
    long = [p for p in _module_paths() if code_shape.module_lines(p) > MODULE_LINES]
    unexplained = [
        f"{_name(p)}: {code_shape.module_lines(p)} lines"
        for p in long
        if _name(p) not in MODULES_NOT_YET_SPLIT
        and LONG_MODULE_REASON
        not in (ast.get_docstring(ast.parse(p.read_text())) or "")
    ]
    assert not unexplained, (
        f"over {MODULE_LINES} lines: split along a seam, or say "
        f"{LONG_MODULE_REASON!r} in the module docstring: {unexplained}"
    )
    stale = sorted(set(MODULES_NOT_YET_SPLIT) - {_name(p) for p in long})
    assert not stale, f"split or gone: remove from MODULES_NOT_YET_SPLIT: {stale}"


def test_no_function_is_long():
    sizes = [s for p in _module_paths() for s in code_shape.function_sizes(p, ROOT)]
    long = {f"{s.module}:{s.name}": s.code_lines for s in sizes}
    long = {k: n for k, n in long.items() if n > FUNCTION_CODE_LINES}
    offenders = sorted(
        f"{k}: {n}" for k, n in long.items() if k not in FUNCTIONS_NOT_YET_SPLIT
    )
    assert not offenders, (
        f"over {FUNCTION_CODE_LINES} lines of code (scripts/code_shape.py): {offenders}"
    )
    stale = sorted(set(FUNCTIONS_NOT_YET_SPLIT) - set(long))
    assert not stale, f"split or gone: remove from FUNCTIONS_NOT_YET_SPLIT: {stale}"


def test_the_allow_lists_name_only_modules_not_yet_split():
    for key in [*MODULES_NOT_YET_SPLIT, *FUNCTIONS_NOT_YET_SPLIT]:
        assert key.startswith("avrisk/rare/"), key


def test_a_function_counts_its_code_not_its_docstring_blanks_or_comments(tmp_path):
    path = tmp_path / "m.py"
    path.write_text(
        "def f(x):\n"
        '    """Doc.\n\n    More doc.\n    """\n'
        "    # a comment\n"
        "    y = (x +\n"
        "         1)\n"
        "\n"
        "    def g():\n"
        "        return y\n"
        "    return g\n"
        "class C:\n"
        "    def m(self):\n"
        "        pass\n"
    )
    sizes = {s.name: s.code_lines for s in code_shape.function_sizes(path, tmp_path)}
    assert sizes == {"f": 5, "f.g": 1, "C.m": 1}


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

"""Every ``avrisk`` command is a thin shell over one library call (issue 43).

The rule, checked on the source with :mod:`ast` (nothing is imported but
``avrisk.cli.app``, which lists the commands):

* The commands are those registered in :mod:`avrisk.cli.app`: every entry of
  ``COMMANDS`` (the top-level group's ``lazy``) and of each subgroup's
  ``lazy`` (``scenarios show``), and every ``avrisk.cli`` function that a
  group callback (``@<typer app>.callback()`` in ``app.py``) calls, which is
  what the group runs without a subcommand (``scenarios``: the listing). The
  callbacks themselves set up the process or dispatch: at most one library
  call each.
* Within a command's body (nested functions and lambdas included, the helpers
  it calls not followed), a *library call* is a call whose callee is a name
  bound by an import, or an attribute of such a name (``avrisk.compare_egos``,
  ``torch.set_num_threads``), that resolves to a module outside
  ``avrisk.cli``, the standard library and the display and option libraries
  (``typer``, ``click``, ``rich``). Builtins, ``avrisk.cli`` helpers (which
  parse options and display), method calls on values, and names used other
  than as a callee (an exception class in ``except``, a constant) are not
  library calls. A class instantiated counts as a call.
* Each command makes library calls to exactly one callee (at one call site
  or several).
"""

import ast
import sys
from importlib.util import find_spec
from pathlib import Path

import pytest

from avrisk.cli.app import COMMANDS, app

#: Top-level modules whose calls are parsing or display, not library work.
DISPLAY = {"typer", "click", "rich"}


def _module_tree(module):
    spec = find_spec(module)
    assert spec is not None and spec.origin is not None, module
    return ast.parse(Path(spec.origin).read_text(), filename=spec.origin)


def _bindings(nodes):
    """Name -> the dotted module path it was imported as, for imports in ``nodes``."""
    bound = {}
    for node in nodes:
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    bound[alias.asname] = alias.name
                else:  # ``import a.b`` binds ``a``
                    top = alias.name.split(".")[0]
                    bound[top] = top
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, "relative imports are not used in avrisk.cli"
            for alias in node.names:
                bound[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return bound


def _module_level(statements):
    """The statements of a module outside functions and classes (``if``/``try`` too)."""
    for node in statements:
        yield node
        if isinstance(node, ast.If | ast.Try):
            for block in (node.body, node.orelse, getattr(node, "finalbody", [])):
                yield from _module_level(block)
            for handler in getattr(node, "handlers", []):
                yield from _module_level(handler.body)


def _dotted(node):
    """``a.b.c`` of a Name/Attribute chain, or None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return ".".join([node.id, *reversed(parts)])


def is_library(qualified):
    top = qualified.split(".")[0]
    if top in DISPLAY or top in sys.stdlib_module_names or top == "__future__":
        return False
    return not (qualified == "avrisk.cli" or qualified.startswith("avrisk.cli."))


def library_calls(tree, function):
    """The distinct library callees of ``function`` in module ``tree``, qualified."""
    (node,) = [
        n
        for n in tree.body
        if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef) and n.name == function
    ]
    bound = _bindings([*_module_level(tree.body), *ast.walk(node)])
    callees = set()
    for call in ast.walk(node):
        if not isinstance(call, ast.Call):
            continue
        name = _dotted(call.func)
        if name is None:
            continue
        head, _, rest = name.partition(".")
        if head not in bound:
            continue  # a builtin, a local value, a helper defined in the module
        qualified = bound[head] + (f".{rest}" if rest else "")
        if is_library(qualified):
            callees.add(qualified)
    return callees


def _subgroup_commands():
    """``(name, module, function)`` of the commands of each subgroup of ``app``."""
    for group in app.registered_groups:
        cls = group.typer_instance.info.cls
        for sub, (module, function) in getattr(cls, "lazy", {}).items():
            yield f"{group.name} {sub}", module, function


def _callbacks():
    """``(name, module, function)`` of the group callbacks of ``app.py``.

    A callback is checked itself (``avrisk`` before any command), and each
    ``avrisk.cli`` function it calls is checked as the command the group runs
    without a subcommand (``scenarios``: the listing).
    """
    tree = _module_tree("avrisk.cli.app")
    for node in tree.body:
        if not isinstance(node, ast.FunctionDef):
            continue
        for deco in node.decorator_list:
            if (
                isinstance(deco, ast.Call)
                and isinstance(deco.func, ast.Attribute)
                and deco.func.attr == "callback"
            ):
                group = _dotted(deco.func.value)
                yield f"{group} (callback)", "avrisk.cli.app", node.name
                bound = _bindings([*_module_level(tree.body), *ast.walk(node)])
                for call in ast.walk(node):
                    name = _dotted(call.func) if isinstance(call, ast.Call) else None
                    where = bound.get(name or "", "")
                    if where.startswith("avrisk.cli."):
                        module, _, function = where.rpartition(".")
                        yield group, module, function


def registered_commands():
    commands = [(name, *where) for name, where in COMMANDS.items()]
    commands += list(_subgroup_commands())
    commands += list(_callbacks())
    return commands


COMMAND_LIST = registered_commands()


def test_every_registered_command_is_found():
    names = {name for name, _, _ in COMMAND_LIST}
    assert set(COMMANDS) <= names
    assert {"scenarios", "scenarios show", "scenarios (callback)"} <= names
    assert "app (callback)" in names


@pytest.mark.parametrize(("name", "module", "function"), COMMAND_LIST)
def test_each_command_makes_one_library_call(name, module, function):
    callees = library_calls(_module_tree(module), function)
    where = f"{name} ({module}.{function}) calls {sorted(callees)}"
    if name.endswith("(callback)"):  # dispatches, or sets up the process
        assert len(callees) <= 1, where
        return
    assert len(callees) == 1, where


def _calls_in(source, function="command"):
    return library_calls(ast.parse(source), function)


def test_the_rule_counts_imports_aliases_attributes_and_local_imports():
    source = """
import avrisk
import numpy as np
from pathlib import Path
from rich.table import Table
from avrisk.cli.common import err_console
from avrisk.scenario import load_spec as read

def helper():
    return 1

def command(x):
    import torch
    from avrisk.api.runs import estimate_spec
    read(x)
    avrisk.compare_egos(x)
    np.zeros(3)
    torch.set_num_threads(1)
    estimate_spec(x)
    estimate_spec(x)
    Path(x); Table(); err_console.print(x); helper(); len(x); x.document()
    (lambda: read(x))()
"""
    assert _calls_in(source) == {
        "avrisk.scenario.load_spec",
        "avrisk.compare_egos",
        "numpy.zeros",
        "torch.set_num_threads",
        "avrisk.api.runs.estimate_spec",
    }


def test_a_command_with_one_library_call_passes_and_two_fail():
    one = (
        "from avrisk.api.runs import estimate_spec\n"
        "def command():\n"
        "    estimate_spec()\n"
    )
    assert _calls_in(one) == {"avrisk.api.runs.estimate_spec"}
    two = one + "    from avrisk.scenario import load_spec\n    load_spec()\n"
    assert len(_calls_in(two)) == 2

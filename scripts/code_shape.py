"""Print avrisk's long modules and long functions, largest first.

Command (from the repository root)::

    python scripts/code_shape.py [PACKAGE_DIR] [--lines 500] [--code 60]

``PACKAGE_DIR`` defaults to this checkout's ``avrisk/``. The source is parsed
(:mod:`ast`), never imported. A module's size is its number of lines; a
function's is its *lines of code*: the lines of its body after the docstring,
blank lines and comment-only lines left out (a nested function counts in its
outer one, and again on its own). ``tests/test_architecture.py`` holds the
package to the same limits.
"""

from __future__ import annotations

import argparse
import ast
import io
import tokenize
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

__all__ = ["FunctionSize", "function_sizes", "module_lines"]

#: A module longer than this says at its top why (``tests/test_architecture.py``).
MODULE_LINES = 500

#: A function with more lines of code than this is split.
FUNCTION_CODE_LINES = 60


class FunctionSize(NamedTuple):
    """One function's lines of code, where it is defined."""

    module: str  # path relative to the package's parent, e.g. avrisk/sim/road.py
    name: str  # qualified within the module, e.g. Simulator.step
    line: int
    code_lines: int


def module_lines(path: Path) -> int:
    """Number of lines of the file at ``path``."""
    return len(path.read_text().splitlines())


def _code_lines(source: str) -> set[int]:
    """Line numbers that hold code: not blank, not only a comment."""
    lines: set[int] = set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type in (
            tokenize.COMMENT,
            tokenize.NL,
            tokenize.NEWLINE,
            tokenize.INDENT,
            tokenize.DEDENT,
            tokenize.ENDMARKER,
        ):
            continue
        lines.update(range(token.start[0], token.end[0] + 1))
    return lines


def function_sizes(path: Path, root: Path) -> Iterator[FunctionSize]:
    """Every function and method in ``path`` with its lines of code.

    Parameters
    ----------
    path : Path
        A Python file.
    root : Path
        What the reported module path is relative to.
    """
    source = path.read_text()
    code = _code_lines(source)
    module = str(path.relative_to(root))

    def visit(node: ast.AST, prefix: str) -> Iterator[FunctionSize]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                yield from visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                body = child.body
                if ast.get_docstring(child) is not None:
                    body = body[1:]
                if body:
                    span = range(body[0].lineno, (child.end_lineno or 0) + 1)
                    size = sum(1 for n in span if n in code)
                else:
                    size = 0
                name = prefix + child.name
                yield FunctionSize(module, name, child.lineno, size)
                yield from visit(child, f"{name}.")
            else:
                yield from visit(child, prefix)

    yield from visit(ast.parse(source, filename=str(path)), "")


def main() -> None:
    """Print the modules over ``--lines`` lines and functions over ``--code``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = Path(__file__).resolve().parents[1] / "avrisk"
    parser.add_argument("package", nargs="?", type=Path, default=default)
    parser.add_argument("--lines", type=int, default=MODULE_LINES)
    parser.add_argument("--code", type=int, default=FUNCTION_CODE_LINES)
    args = parser.parse_args()
    root = args.package.resolve().parent
    files = sorted(args.package.resolve().rglob("*.py"))
    modules = sorted((module_lines(p), str(p.relative_to(root))) for p in files)
    long_modules = [(n, m) for n, m in modules if n > args.lines]
    print(f"{len(files)} modules, {sum(n for n, _ in modules)} lines;", end=" ")
    print(f"{len(long_modules)} over {args.lines} lines:")
    for n, m in sorted(long_modules, reverse=True):
        print(f"  {n:5d}  {m}")
    functions = [s for p in files for s in function_sizes(p, root)]
    long_functions = sorted(
        (s for s in functions if s.code_lines > args.code),
        key=lambda s: -s.code_lines,
    )
    print(f"{len(functions)} functions; {len(long_functions)} over", end=" ")
    print(f"{args.code} lines of code:")
    for s in long_functions:
        print(f"  {s.code_lines:5d}  {s.module}:{s.line}  {s.name}")


if __name__ == "__main__":
    main()

"""Docstrings and comments say what and why; measurements live in BENCHMARKS.md.

A docstring or comment of ``avrisk/`` may give the reason for a choice and cite
the BENCHMARKS.md section that measured it (``BENCHMARKS.md, "Coverage"``), but
not the measurement itself: no date of a measurement (``2026-11-25``), no
timing (``1.8 ms``, ``took 440 s``, ``3 minutes``) and no speed-up claim
(``15-24% faster``, ``gained 6%``, ``1,040 rollouts per second``). Those go out
of date with every change of code or machine; BENCHMARKS.md records them with
their command and date.

What is not a timing: physical durations of the simulated world (``dt 0.1 s``,
a ``15 s`` window, ``min TTC <= 0.1 s``), which are given in seconds, and code
literals in double backquotes (a format example such as ``"7 min 20 s"``).
Docstrings are read with :mod:`ast`, comments with :mod:`tokenize`; a
citation is found as ``tests/test_docs.py`` finds it (and checked there).
"""

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

from tests.test_docs import CITATION

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "avrisk"

#: A date of the form a measurement is stamped with.
DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")
_WORDS = "one|two|three|four|five|six|seven|eight|nine|ten|twelve|twenty|thirty"
_NUMBER = rf"(?:\d(?:[\d.,]*\d)?|\b(?:{_WORDS})\b)"
_RANGE = rf"{_NUMBER}(?:[ \t]*(?:-|–|to)[ \t]*{_NUMBER})?"
#: Timings of computation. Sub-second units and minutes or hours are never the
#: simulated world's (its durations are in seconds); seconds count when they
#: are what something took or cost.
TIMING = re.compile(
    rf"{_RANGE}[ \t]*(?:(?-i:ms|µs|us|ns)|(?:milli|micro)seconds?"
    r"|min|minutes?|h|hours?)\b"
    r"|\ba\s+minute\b"
    rf"|\b(?:took|takes|take|taking|spent|spends|lasted|costs?)\s+"
    rf"(?:about\s+|under\s+|over\s+|only\s+|some\s+)?{_RANGE}[ \t]*(?:s|seconds?)\b"
    rf"|{_RANGE}[ \t]*(?:s|seconds?)\s+(?:per|a|an|each)\s+"
    r"(?:step|rollout|process|command|call|chunk|batch|run|iteration|frame)\b",
    re.IGNORECASE,
)
#: Speed-up claims and throughputs.
SPEED = re.compile(
    rf"{_RANGE}[ \t]*(?:%|x|×|times)\s+(?:faster|slower|quicker|speed-?up|as fast)\b"
    rf"|\b(?:gain|gains|gained|saves?|saved|cuts?)\s+(?:about\s+)?{_RANGE}[ \t]*%"
    rf"|{_RANGE}[ \t]*(?:x|×|times)\s+(?:the\s+)?(?:\w+\s+)?(?:throughput|speed)\b"
    rf"|{_RANGE}[ \t]*(?:rollouts|steps|samples|calls|frames|images)[ \t]*"
    r"(?:per[ \t]+second|/[ \t]*s)\b",
    re.IGNORECASE,
)
#: A code literal: an example of a format, not a measurement.
LITERAL = re.compile(r"``[^`]+``")

#: Modules (or folders, ending in ``/``) being rewritten on another branch,
#: whose flagged docstrings and comments are cleaned when it merges; every
#: module is clean now. A module here is still scanned for everything else it
#: does not flag.
NOT_YET_CLEANED: set[str] = set()


def _blank(match):
    return re.sub(r"[^\n]", " ", match.group(0))


def _findings(text):
    """``(line offset, kind, excerpt)`` for each measurement in ``text``."""
    text = LITERAL.sub(_blank, CITATION.sub(_blank, text))
    found = []
    for kind, pattern in (("date", DATE), ("timing", TIMING), ("speed-up", SPEED)):
        for match in pattern.finditer(text):
            line = text.count("\n", 0, match.start())
            found.append((line, kind, match.group(0)))
    return found


def _docstrings(tree):
    kinds = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)
    for node in ast.walk(tree):
        if isinstance(node, kinds) and ast.get_docstring(node, clean=False):
            yield node.body[0].value.lineno, ast.get_docstring(node, clean=False)


def _comments(source):
    """Comments on consecutive lines as one text: a citation may run over them."""
    tokens = tokenize.generate_tokens(io.StringIO(source).readline)
    blocks = []
    for token in tokens:
        if token.type != tokenize.COMMENT:
            continue
        line, text = token.start[0], token.string.lstrip("#:")
        if blocks and blocks[-1][0] + blocks[-1][1].count("\n") == line - 1:
            blocks[-1] = (blocks[-1][0], blocks[-1][1] + "\n" + text)
        else:
            blocks.append((line, text))
    return blocks


def measurements_in(path):
    """``"path:line: kind 'excerpt'"`` per measurement in docstrings and comments."""
    source = path.read_text(encoding="utf-8")
    texts = list(_docstrings(ast.parse(source))) + _comments(source)
    name = path.relative_to(ROOT).as_posix()
    return sorted(
        f"{name}:{first + offset}: {kind} {excerpt!r}"
        for first, text in texts
        for offset, kind, excerpt in _findings(text)
    )


def _exempt(name):
    return any(
        name == entry or (entry.endswith("/") and name.startswith(entry))
        for entry in NOT_YET_CLEANED
    )


def _modules():
    return sorted(PACKAGE.rglob("*.py"))


def test_no_docstring_or_comment_of_avrisk_holds_a_measurement():
    found = [
        line
        for path in _modules()
        if not _exempt(path.relative_to(ROOT).as_posix())
        for line in measurements_in(path)
    ]
    assert not found, "measurements belong in BENCHMARKS.md:\n" + "\n".join(found)


def test_every_module_left_to_clean_still_exists():
    for entry in NOT_YET_CLEANED:
        assert (ROOT / entry).exists(), f"{entry} is gone: drop it from the list"


@pytest.mark.parametrize(
    "text",
    [
        "It took 440 s on two cores.",
        "1.8 ms instead of 2.5 ms per step",
        "gained 6% compiled and 15-24% eager",
        "about 3-4x faster at large batches",
        "2.0 until the drivers of 2026-11-25 (sixth look)",
        "at about 590 rollouts per second",
        "a chunk takes about 10 s per process",
        "which took 3 minutes",
        "about 250 microseconds a call",
        "about seven minutes on one core",
        "after a compilation of about a minute per new batch size",
        "about three times the eager throughput at batch 1024",
    ],
)
def test_a_measurement_is_found(text):
    assert _findings(text)


@pytest.mark.parametrize(
    "text",
    [
        "Time step dt [s], 0.1 s in the bundled scenarios.",
        "P(min TTC <= 0.1 s) per 10-s rollout from P0",
        "Steps per window (15 s), back-propagated through in full.",
        'the figures are in BENCHMARKS.md, "Simulator throughput".',
        'held-out replays (BENCHMARKS.md ("Training on top of the brake\n'
        '(2026-11-25, sixth look)")',
        '# as measured (BENCHMARKS.md, "An emergency brake on the learned drivers:\n'
        '# --brake-guard (2026-11-25, fourth look")',
        'a duration for a person: ``"7 min 20 s"``, ``"2 h 05 min"``',
        "acceleration [m/s^2], 15 m/s overtake",
    ],
)
def test_what_is_not_a_measurement_is_not_found(text):
    assert not _findings(text)

"""The docs hold together: links resolve, cited sections exist, examples run.

* Every relative link of the README, BENCHMARKS.md and ``docs/*.md`` names a
  file that exists and, with ``#anchor``, a heading of that file (GitHub's
  anchors).
* Every citation of a BENCHMARKS.md section in the code, tests, benchmarks,
  scripts, bundled data and docs (``BENCHMARKS.md, "Title"``,
  ``BENCHMARKS.md "Title"`` or ``BENCHMARKS.md ("Title"``) starts a heading
  of BENCHMARKS.md or of its archive (``docs/benchmarks-history.md``, the
  superseded sections), and BENCHMARKS.md links every archived section.
* Every ``benchmarks/...`` path that BENCHMARKS.md, its archive, the README or
  ``docs/*.md`` name exists: a results file, folder or script.
* ``docs/design.md`` states the import rules that ``tests/test_architecture.py``
  checks, and its layout lists every package.
* The Python examples of ``docs/*.md`` run, each page in a fresh interpreter
  (the README's run in ``tests/test_readme.py``).
"""

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_architecture import ALLOWED

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "BENCHMARKS.md"
#: The superseded sections of BENCHMARKS.md, word for word.
ARCHIVE = ROOT / "docs" / "benchmarks-history.md"
DESIGN = ROOT / "docs" / "design.md"
PAGES = sorted([ROOT / "README.md", BENCHMARKS, *(ROOT / "docs").glob("*.md")])

#: ``[text](target)``; images too. Targets with a scheme are not checked.
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
#: A citation of a BENCHMARKS.md section, the title possibly over lines.
CITATION = re.compile(r'BENCHMARKS\.md(?:,\s*|\s+|\s*\(\s*)\(?"([^"]+)"')
#: Where citations may stand.
CITING = ("avrisk", "tests", "benchmarks", "scripts", "docs")
CITING_SUFFIXES = {".py", ".md", ".yaml", ".yml", ".sh"}


def _outside_code(text):
    """``text`` without fenced code blocks (a link there is an example)."""
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)


def headings(path):
    """The headings of a Markdown file, outside code blocks, as written."""
    text = _outside_code(path.read_text(encoding="utf-8"))
    return [m.group(1).strip() for m in re.finditer(r"^#{1,6} (.+)$", text, re.M)]


def slug(heading):
    """GitHub's anchor of a heading: lower case, punctuation dropped, - for space."""
    text = heading.strip().lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path):
    """Every anchor of a Markdown file, repeated headings numbered as GitHub does."""
    seen = {}
    out = set()
    for heading in headings(path):
        base = slug(heading)
        n = seen.get(base, 0)
        out.add(base if n == 0 else f"{base}-{n}")
        seen[base] = n + 1
    return out


def _links(page):
    text = _outside_code(page.read_text(encoding="utf-8"))
    text = re.sub(r"`[^`\n]*`", "", text)  # a link in code is an example
    return [t for t in LINK.findall(text) if not re.match(r"[a-z]+:", t)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_resolves(page):
    broken = []
    for target in _links(page):
        file, _, anchor = target.partition("#")
        path = (page.parent / file).resolve() if file else page
        if not path.exists():
            broken.append(f"{target}: no file {path.relative_to(ROOT)}")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            broken.append(f"{target}: no heading with that anchor")
    assert not broken, broken


def test_the_anchor_of_a_heading_is_githubs():
    assert slug("Large naive references (2026-11-23/24)") == (
        "large-naive-references-2026-11-2324"
    )
    assert slug("`highway_sampled`: the drivers' action noise in X") == (
        "highway_sampled-the-drivers-action-noise-in-x"
    )


def normalized(title):
    """A title as prose cites it: no backquotes, no comment marks, one space."""
    title = re.sub(r"\n\s*(?:#:?|//)?\s*", " ", title)
    return " ".join(title.replace("`", "").split())


def citations():
    """``(file, title)`` for every BENCHMARKS.md section cited in the sources."""
    found = []
    for top in CITING:
        for path in sorted((ROOT / top).rglob("*")):
            if path.suffix not in CITING_SUFFIXES or "results" in path.parts:
                continue
            if path.name in ("test_docs.py", "test_docstrings.py"):
                continue  # they show the pattern, not a citation
            text = path.read_text(encoding="utf-8", errors="replace")
            for match in CITATION.finditer(text):
                found.append((path.relative_to(ROOT).as_posix(), match.group(1)))
    return found


def test_the_sources_cite_benchmark_sections():
    cited = {file for file, _ in citations()}
    assert "avrisk/rare/estimator.py" in cited  # the pattern finds them at all


def test_every_cited_benchmark_section_exists():
    titles = [normalized(h) for h in headings(BENCHMARKS) + headings(ARCHIVE)]
    missing = [
        f"{file}: {title!r}"
        for file, title in citations()
        if not any(h.startswith(normalized(title)) for h in titles)
    ]
    assert not missing, missing


def test_benchmarks_links_every_archived_section():
    # The archive keeps the headings its sections stood under; every other
    # heading there is a moved section that BENCHMARKS.md must point to.
    here = set(headings(BENCHMARKS))
    text = BENCHMARKS.read_text(encoding="utf-8")
    linked = set(re.findall(r"\]\(docs/benchmarks-history\.md#([^)\s]+)\)", text))
    moved = [h for h in headings(ARCHIVE)[1:] if h not in here]
    unlisted = [h for h in moved if slug(h) not in linked]
    assert not unlisted, unlisted


#: ``benchmarks/...`` as prose names it; the trailing punctuation is the prose's.
RESULTS_PATH = re.compile(r"(?<![\w/.])benchmarks/[\w./{},*<>-]*[\w*}/]")
#: Files renamed after a section named them: the files of the drivers
#: ``a3228f24`` got the suffix ``_drivers_a3228f24`` when the drivers changed
#: (the sections naming the first and the last say so).
RENAMED = {
    "benchmarks/results/coverage/highway_default_shrunk.jsonl": (
        "benchmarks/results/coverage/highway_default_shrunk_drivers_a3228f24.jsonl"
    ),
    "benchmarks/results/coverage/highway_default_slope.jsonl": (
        "benchmarks/results/coverage/highway_default_slope_drivers_a3228f24.jsonl"
    ),
    "benchmarks/results/references/highway_vision": (
        "benchmarks/results/references/highway_vision_drivers_a3228f24.json"
    ),
}
#: Placeholders of the commands' prose: any name.
PLACEHOLDER = re.compile(r"<[^>]*>|(?<![A-Za-z])SCENARIO(?![A-Za-z])")


def _named_paths(page):
    """``(as written, glob pattern)`` for the ``benchmarks/...`` paths of a page.

    A brace list expands; ``SCENARIO`` or ``<...>`` stands for any name; a
    reference's ``--out`` prefix names the files it writes (``PREFIX.json``).
    """
    out = []
    for path in sorted(set(RESULTS_PATH.findall(page.read_text(encoding="utf-8")))):
        for name in _expand_braces(path):
            out.append((path, PLACEHOLDER.sub("*", RENAMED.get(name, name))))
    return out


def _expand_braces(path):
    """``a_{x,y}_b`` as ``[a_x_b, a_y_b]``; a path without braces alone."""
    brace = re.search(r"\{([^}]*)\}", path)
    if not brace:
        return [path]
    head, tail = path[: brace.start()], path[brace.end() :]
    return [head + option + tail for option in brace.group(1).split(",")]


@pytest.mark.parametrize(
    "page",
    [ROOT / "README.md", BENCHMARKS, *(ROOT / "docs").glob("*.md")],
    ids=lambda p: p.relative_to(ROOT).as_posix(),
)
def test_every_benchmarks_path_named_exists(page):
    missing = _unresolved(_named_paths(page))
    assert not missing, missing


def _unresolved(named):
    """The paths as written of ``named`` that no file or folder matches."""
    return [
        written
        for written, pattern in named
        if not any(ROOT.glob(pattern)) and not any(ROOT.glob(pattern + ".*"))
    ]


def test_named_paths_are_checked_at_all():
    named = dict(_named_paths(BENCHMARKS))
    assert "benchmarks/results/exact_suite/after52_splitting_is.jsonl" in named
    assert "benchmarks/results/coverage/highway_{idm,default}_slope.jsonl" in named
    assert named["benchmarks/results/references/SCENARIO.json"] == (
        "benchmarks/results/references/*.json"
    )
    absent = ("x", "benchmarks/results/references/no_such_scenario.json")
    prefix = ("y", "benchmarks/results/references/highway_idm")
    assert _unresolved([absent, prefix]) == ["x"]


def _design_rules():
    table = DESIGN.read_text(encoding="utf-8").split("| package | may import", 1)[1]
    rules = {}
    for row in re.finditer(r"^\| `(\w+)` \| ([^|]*) \|", table, flags=re.M):
        rules[row.group(1)] = set(re.findall(r"`(\w+)`", row.group(2)))
    return rules


def test_the_design_notes_state_the_import_rules_the_architecture_test_checks():
    assert _design_rules() == ALLOWED


def test_the_design_layout_lists_every_package():
    layout = DESIGN.read_text(encoding="utf-8").split("## Layout", 1)[1]
    layout = layout.split("```", 2)[1]
    root = ROOT / "avrisk"
    packages = sorted(
        f"avrisk/{p.parent.relative_to(root)}/"
        for p in root.rglob("__init__.py")
        if p.parent != root
    )
    data = sorted(f"{p.name}/" for p in (root / "data").iterdir() if p.is_dir())
    missing = [p for p in packages if p not in layout]
    assert not missing, missing
    assert all(folder in layout for folder in data)


def _pages_with_examples():
    pages = sorted((ROOT / "docs").glob("*.md"))
    return [p for p in pages if "```python" in p.read_text(encoding="utf-8")]


@pytest.mark.parametrize(
    "page", _pages_with_examples(), ids=lambda p: p.relative_to(ROOT).as_posix()
)
def test_the_python_examples_of_a_docs_page_run(page, tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
    script = tmp_path / "blocks.py"
    script.write_text("\n\n".join(blocks))
    done = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-3000:]

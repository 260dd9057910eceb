"""Provenance stamps: what defines a probability, and how it was computed.

A run's estimate is of ``p = P0(f(X) <= gamma)`` for one resolved scenario and
one set of learned weights: those *define* ``p``, and two runs may only be
compared (or one used as the other's reference) when they agree on them. The
code version, device and precision say how it was *computed*: differences
there are shown, not refused. Every run summary and every reference carries
such a stamp::

    {"defines_p": {"scenario_sha256": ..., "weights_sha256": {...}},
     "computed_with": {"avrisk": ..., "git_commit": ..., "device": ...,
                       "precision": ..., "torch": ...}}
"""

from __future__ import annotations

import subprocess
import tomllib
from pathlib import Path
from typing import Any

import avrisk.version
from avrisk.fingerprint import sha256_file, sha256_json

__all__ = [
    "ProvenanceMismatchError",
    "check_same_definition",
    "code_version",
    "sha256_file",
    "sha256_json",
    "stamp",
]


class ProvenanceMismatchError(ValueError):
    """Two results estimate different probabilities (scenario or weights differ)."""


def code_version() -> dict[str, Any]:
    """The version of avrisk, and its git commit when run from an avrisk checkout.

    Returns
    -------
    dict
        ``avrisk`` (version), ``git_commit`` (hex or None), ``git_dirty``
        (uncommitted changes to tracked files; None outside a checkout).
        The commit is avrisk's only where the package's folder is the top of
        a git work tree whose ``pyproject.toml`` names avrisk: a package
        installed in a virtual environment inside a user's repository is not
        stamped with the user's commit.
    """
    root = Path(avrisk.version.__file__).resolve().parents[1]
    top = _git(root, "rev-parse", "--show-toplevel")
    checkout = top is not None and Path(top).resolve() == root and _names_avrisk(root)
    commit = _git(root, "rev-parse", "HEAD") if checkout else None
    dirty = (
        _git(root, "status", "--porcelain", "--untracked-files=no") if commit else None
    )
    return {
        "avrisk": avrisk.version.__version__,
        "git_commit": commit,
        "git_dirty": None if commit is None or dirty is None else bool(dirty),
    }


def _git(root: Path, *args: str) -> str | None:
    """The output of ``git -C root ARGS``, or None where it fails (no git, no repo)."""
    try:
        done = subprocess.run(
            ["git", "-C", str(root), *args],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip()


def _names_avrisk(root: Path) -> bool:
    """Whether ``root/pyproject.toml`` is avrisk's own (``[project] name``)."""
    try:
        project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError):
        return False
    return isinstance(project, dict) and project.get("name") == "avrisk"


def stamp(defines_p: dict[str, Any], computed_with: dict[str, Any]) -> dict[str, Any]:
    """A provenance stamp: the definition of ``p`` and how it was computed.

    Parameters
    ----------
    defines_p : dict
        Hashes of what defines ``p`` (scenario, weights).
    computed_with : dict
        Device, precision and the like; the code version is added here.
    """
    return {
        "defines_p": defines_p,
        "computed_with": {**code_version(), **computed_with},
    }


def check_same_definition(
    mine: dict[str, Any] | None, theirs: dict[str, Any] | None, what: str
) -> list[str]:
    """Refuse to pair two results that estimate different probabilities.

    Parameters
    ----------
    mine, theirs : dict or None
        Provenance stamps (None: a result recorded before stamps existed).
    what : str
        What ``theirs`` is, for messages (``"the reference run"``).

    Returns
    -------
    list of str
        Notes on how the computations differ (device, precision, code), and on
        a missing stamp: to show, not to refuse.

    Raises
    ------
    ProvenanceMismatchError
        If both are stamped and their ``defines_p`` differ.
    """
    if mine is None or theirs is None:
        return [
            f"{what} or this run has no provenance stamp: cannot check that "
            "they estimate the same probability"
        ]
    a, b = mine["defines_p"], theirs["defines_p"]
    if a != b:
        keys = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
        raise ProvenanceMismatchError(
            f"{what} estimates a different probability (differs in: "
            f"{', '.join(keys)}): it was computed for another scenario or other "
            "learned weights; compute a new one"
        )
    c, d = mine["computed_with"], theirs["computed_with"]
    return [
        f"{what} was computed with {key} = {d.get(key)!r} (this run: {c.get(key)!r})"
        for key in sorted(set(c) | set(d))
        if c.get(key) != d.get(key) and key != "git_dirty"
    ]

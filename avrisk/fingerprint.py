"""SHA-256 fingerprints of JSON values and files (a leaf: imports nothing of avrisk).

What defines a probability (a resolved scenario, learned weights) is recorded
by these hashes in provenance stamps (:mod:`avrisk.pipeline.provenance`).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

__all__ = ["sha256_file", "sha256_json"]


def sha256_json(value: Any) -> str:
    """SHA-256 of a JSON value in canonical form (sorted keys, no spaces).

    Examples
    --------
    >>> sha256_json({"b": 1, "a": [2.0]}) == sha256_json({"a": [2.0], "b": 1})
    True
    """
    text = json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def sha256_file(path: Path) -> str:
    """SHA-256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()

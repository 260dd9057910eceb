"""The run directory's layout: its files' names, its chunk files' names, its error.

What each file holds: :mod:`avrisk.pipeline.store`. This module is a leaf of
the package, so that the lock, the manifest and the chunk files name the same
files and raise the same error without importing the run directory.
"""

from __future__ import annotations

import re
from pathlib import Path

__all__ = [
    "CHECKPOINT_FILE",
    "CHUNKS_DIR",
    "CONFIG_FILE",
    "LOCK_FILE",
    "SAMPLES_FILE",
    "SUMMARY_FILE",
    "SUMMARY_SCHEMA",
    "RunDirectoryError",
    "chunk_key",
    "chunk_name",
    "is_chunk_name",
]

SUMMARY_SCHEMA = "avrisk.summary/1"
CONFIG_FILE = "config.json"
SUMMARY_FILE = "summary.json"
SAMPLES_FILE = "samples.parquet"
CHECKPOINT_FILE = "checkpoint.json"
CHUNKS_DIR = "chunks"
LOCK_FILE = ".lock"

_CHUNK_NAME = re.compile(r"stage(\d{4,7})-chunk(\d{6})\.parquet")


class RunDirectoryError(ValueError):
    """The output directory cannot be used for this run (says why and what to do)."""


def chunk_name(stage: int, chunk: int) -> str:
    """The file name of chunk ``chunk`` of stage ``stage`` in ``chunks/``.

    Examples
    --------
    >>> chunk_name(1, 23)
    'stage0001-chunk000023.parquet'
    """
    return f"stage{stage:04d}-chunk{chunk:06d}.parquet"


def is_chunk_name(name: str) -> bool:
    """Whether ``name`` is a chunk file's name (:func:`chunk_name`)."""
    return _CHUNK_NAME.fullmatch(name) is not None


def chunk_key(path: Path) -> tuple[int, int]:
    """``(stage, chunk)`` of a chunk file's name."""
    match = _CHUNK_NAME.fullmatch(path.name)
    if match is None:
        raise RunDirectoryError(f"{path}: not a chunk file name")
    return int(match[1]), int(match[2])

"""The run directory's manifest: what each record held when it was written.

``manifest.json`` records, for every chunk file, its stage, chunk index, row
count and the SHA-256 of its bytes, updated (atomically) right after the chunk
is written; when the run finishes, the digests of ``samples.parquet`` and
``summary.json`` as well. Records are checked against it when read, so a
chunk copied from another stage or run, a chunk or summary with altered
values, a truncated file or a deleted chunk is named (file, expected vs found)
and never trusted: a chunk is evaluated again, a summary or samples table is
refused (the message says to rerun the command, which recomputes it).

Crash safety: a chunk is written before its manifest entry, so ``kill -9``
between the two leaves a chunk the manifest does not list. Such a chunk is
evaluated again rather than trusted on its content: at most the chunks in
flight at the kill are lost, and no rule about what a "plausible" chunk looks
like has to be right (a swapped-in valid chunk is plausible by construction).

A digest defends against damage and accidental swaps only: someone who
rewrites the manifest too can make any records pass. Directories written
before the manifest existed have none; they are read unverified (with a
:class:`RecordIntegrityWarning` saying so).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from avrisk.pipeline.files import write_json
from avrisk.pipeline.layout import RunDirectoryError

MANIFEST_FILE = "manifest.json"
MANIFEST_SCHEMA = "avrisk.manifest/1"


class RecordIntegrityWarning(UserWarning):
    """A record of the run directory did not match the manifest (or has none)."""


def digest(data: bytes) -> str:
    """SHA-256 (hex) of ``data``."""
    return hashlib.sha256(data).hexdigest()


def file_digest(path: Path) -> str:
    """SHA-256 (hex) of the file at ``path``, read in blocks."""
    h = hashlib.sha256()
    with path.open("rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class Manifest:
    """``DIR/manifest.json``: read once, rewritten atomically on every change."""

    def __init__(self, directory: Path) -> None:
        self.file = directory / MANIFEST_FILE
        self._record: dict[str, Any] | None = None
        self._stamp: tuple[int, int] | None = None

    @property
    def exists(self) -> bool:
        """Whether the directory has a manifest (runs before it existed have none)."""
        return self._record is not None or self.file.is_file()

    def create(self) -> None:
        """Write an empty manifest (a new run directory)."""
        self._record = {"schema": MANIFEST_SCHEMA, "chunks": {}}
        self._save()

    def record(self) -> dict[str, Any]:
        """The manifest's content (read, and checked for shape, when it changed)."""
        if self._record is not None and self._stamp != self._file_stamp():
            self._record = None  # changed on disk since: the file is the truth
        if self._record is None:
            try:
                record = json.loads(self.file.read_text())
            except (OSError, ValueError) as exc:
                raise self._error(f"unreadable ({exc})") from None
            ok = (
                isinstance(record, dict)
                and record.get("schema") == MANIFEST_SCHEMA
                and isinstance(record.get("chunks"), dict)
                and all(
                    isinstance(e, dict)
                    and all(isinstance(e.get(k), int) for k in ("stage", "chunk"))
                    and isinstance(e.get("rows"), int)
                    and isinstance(e.get("sha256"), str)
                    for e in record["chunks"].values()
                )
            )
            if not ok:
                raise self._error(f"not an {MANIFEST_SCHEMA} record")
            self._record = record
            self._stamp = self._file_stamp()
        return self._record

    def chunk(self, name: str) -> dict[str, Any] | None:
        """The entry of chunk file ``name``, or None."""
        return self.record()["chunks"].get(name)

    def add_chunk(self, name: str, stage: int, chunk: int, rows: int, sha: str) -> None:
        """Record a chunk file just written."""
        self.record()["chunks"][name] = {
            "stage": stage,
            "chunk": chunk,
            "rows": rows,
            "sha256": sha,
        }
        self._save()

    def entry(self, key: str) -> dict[str, Any] | None:
        """The entry of ``samples`` or ``summary`` (None before the run finished)."""
        entry = self.record().get(key)
        return entry if isinstance(entry, dict) else None

    def set_entries(self, **entries: dict[str, Any] | None) -> None:
        """Set (or with None remove) the ``samples`` / ``summary`` entries."""
        record = self.record()
        for key, value in entries.items():
            if value is None:
                record.pop(key, None)
            else:
                record[key] = value
        self._save()

    def _save(self) -> None:
        assert self._record is not None
        write_json(self.file, self._record)
        self._stamp = self._file_stamp()

    def _file_stamp(self) -> tuple[int, int] | None:
        try:
            stat = self.file.stat()
        except OSError:
            return None
        return stat.st_size, stat.st_mtime_ns

    def _error(self, what: str) -> Exception:
        return RunDirectoryError(
            f"{self.file}: {what}; its records cannot be verified: delete the run "
            "directory and run again"
        )

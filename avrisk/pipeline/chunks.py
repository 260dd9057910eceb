"""A run's chunk files: each evaluated chunk, recorded, checked, replayed.

While a run goes on, every evaluated chunk is one Parquet file in
``chunks/`` (:func:`~avrisk.pipeline.layout.chunk_name`), in the samples-table
format (:mod:`avrisk.pipeline.samples`), written before its entry in the
manifest (:mod:`avrisk.pipeline.manifest`). A resumed run replays the chunks
that verify against their entries (:meth:`ChunkFiles.cached`) and evaluates
the others again; the columns of large blocks a chunk left out are drawn
again when read (:mod:`avrisk.pipeline.regenerate`).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from avrisk.pipeline.files import parquet_bytes, write_atomic
from avrisk.pipeline.layout import (
    RunDirectoryError,
    chunk_key,
    chunk_name,
    is_chunk_name,
)
from avrisk.pipeline.manifest import (
    MANIFEST_FILE,
    Manifest,
    RecordIntegrityWarning,
    digest,
)
from avrisk.pipeline.regenerate import PROPOSALS_FILE, Regenerator, chunk_meta
from avrisk.pipeline.samples import (
    BOOKKEEPING,
    DENSITIES,
    leaving_out,
    samples_table,
)
from avrisk.rare import StageBatch
from avrisk.rare.problem import FINAL_STAGE

__all__ = ["ChunkFiles"]


class ChunkFiles:
    """The ``chunks/`` folder of a run directory.

    Parameters
    ----------
    folder : Path
        ``DIR/chunks``.
    param_names : sequence of str
        Names of the ``D`` coordinates of ``X``.
    units : mapping of str to str
        Unit of each parameter (and of ``f``), recorded as field metadata.
    manifest : Manifest
        The run directory's manifest (a chunk is listed there once written).
    regenerator : Regenerator or None
        Leaves large blocks out of the chunks drawn fresh and draws them
        again when read; None stores (and needs) every column.
    store_full : bool
        Store every column even with a ``regenerator``.
    """

    def __init__(
        self,
        folder: Path,
        param_names: Sequence[str],
        units: Mapping[str, str],
        manifest: Manifest,
        regenerator: Regenerator | None,
        store_full: bool,
    ) -> None:
        self.folder = folder
        self.param_names = list(param_names)
        self.units = dict(units)
        self.store_full = store_full
        self._manifest = manifest
        self._regenerator = regenerator

    def final_stage(self, columns: Sequence[str]) -> pa.Table:
        """Columns of the final stage's recorded chunks (before the run finishes).

        Columns a chunk lacks (recorded by an older avrisk) are null there.
        """
        files = [
            p
            for p in self.checked_files()
            if p.name.startswith(f"stage{FINAL_STAGE:04d}-")
        ]
        tables = []
        for path in files:
            table = self.read(path, columns)
            present = set(table.column_names)
            tables.append(
                pa.table(
                    {
                        c: table[c] if c in present else pa.nulls(len(table))
                        for c in columns
                    }
                )
            )
        return pa.concat_tables(tables, promote_options="default")

    def path(self, stage: int, chunk: int) -> Path:
        """Where chunk ``chunk`` of stage ``stage`` is recorded."""
        return self.folder / chunk_name(stage, chunk)

    def record(self, batch: StageBatch) -> pa.Table:
        """Store one evaluated chunk (atomically), large blocks left out if it can.

        The chunk is written first, then its manifest entry: a chunk that a
        kill left unlisted is evaluated again (see :meth:`cached`).

        Returns
        -------
        pyarrow.Table
            The rows as written (for
            :func:`~avrisk.pipeline.sizing.marginal_row_bytes`).
        """
        table = samples_table(batch, self.param_names, self.units)
        if self._regenerator is not None and not self.store_full:
            meta = self._regenerator.leave_out(batch)
            if meta is not None:
                table = leaving_out(table, meta)
        self.write(table, batch.stage, batch.chunk)
        return table

    def write(self, table: pa.Table, stage: int, chunk: int) -> None:
        """Write a chunk's rows atomically, then its manifest entry."""
        path = self.path(stage, chunk)
        data = parquet_bytes(table)
        write_atomic(path, data)
        if self._manifest.exists:
            self._manifest.add_chunk(
                path.name, stage, chunk, table.num_rows, digest(data)
            )

    def cached(self, stage: int, chunk: int) -> StageBatch | None:
        """The recorded chunk ``(stage, chunk)``, or ``None`` to evaluate it.

        A chunk that does not match its manifest entry (digest, rows, stage),
        is missing though listed, or is not listed (written as a kill stopped
        the run, or copied in) is named in a :class:`RecordIntegrityWarning`
        and evaluated again, never replayed. Without a manifest (a directory
        from before it existed) only its stage and chunk columns are checked.
        """
        path = self.path(stage, chunk)
        listed = self._manifest.exists and self._manifest.chunk(path.name) is not None
        if not path.is_file():
            if listed:
                warnings.warn(
                    f"{path}: listed in {MANIFEST_FILE} but missing; evaluated again",
                    RecordIntegrityWarning,
                    stacklevel=2,
                )
            return None
        data = path.read_bytes()
        problem = self._problem(path, data, stage, chunk)
        if problem is not None:
            warnings.warn(
                f"{path}: {problem}; evaluated again",
                RecordIntegrityWarning,
                stacklevel=2,
            )
            path.unlink()
            return None
        table = self.read(path, data=data)
        cols = {name: table.column(name).to_numpy() for name in table.column_names}
        x = np.column_stack([cols[name] for name in self.param_names])
        known = set(BOOKKEEPING + DENSITIES + tuple(self.param_names))
        extras = {k: v for k, v in cols.items() if k not in known}
        return StageBatch(
            stage=stage,
            chunk=chunk,
            ids=cols["sample_id"],
            x=x,
            values=cols["f"],
            extras=extras,
            log_p0=cols["log_p0"],
            log_q=cols["log_p_proposal"],
            seeds=cols["seed"],
        )

    def recorded_outcomes(self) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
        """``(stage, chunk, f, failed)`` of every chunk file, first stage first.

        Only the ``f`` and ``status`` columns are read, unverified: to choose
        rows cheaply among millions. :meth:`cached` verifies a chunk before
        its rows are used; an unreadable file is left out.
        """
        found = []
        for path in sorted(self.folder.glob("*.parquet")):
            if not is_chunk_name(path.name):
                continue
            try:
                parquet = pq.ParquetFile(path)
                names = parquet.schema_arrow.names
                table = parquet.read(columns=[c for c in ("f", "status") if c in names])
            except (pa.ArrowException, OSError):
                continue
            f = table["f"].to_numpy()
            failed = np.zeros(len(f), dtype=bool)
            if "status" in names:  # null in chunks of an older avrisk
                status = table["status"].to_numpy(zero_copy_only=False)
                failed = np.nan_to_num(status.astype(float)) != 0
            found.append((*chunk_key(path), f, failed))
        return sorted(found, key=lambda c: (c[0] == FINAL_STAGE, c[0], c[1]))

    def _problem(self, path: Path, data: bytes, stage: int, chunk: int) -> str | None:
        """What is wrong with chunk file ``path`` holding ``data``, or None."""
        entry = self._manifest.chunk(path.name) if self._manifest.exists else None
        if self._manifest.exists:
            if entry is None:
                return (
                    f"not listed in {MANIFEST_FILE} (written as the run was "
                    "stopped, or copied in)"
                )
            found = digest(data)
            if found != entry["sha256"]:
                return (
                    f"SHA-256 {found[:16]} ({len(data)} bytes) differs from the "
                    f"{entry['sha256'][:16]} recorded in {MANIFEST_FILE} (changed, "
                    "truncated or swapped)"
                )
        try:
            parquet = pq.ParquetFile(pa.BufferReader(data))
            names = parquet.schema_arrow.names
            table = parquet.read(columns=[c for c in ("stage", "chunk") if c in names])
        except (pa.ArrowException, OSError) as exc:
            return f"not a readable Parquet file ({str(exc)[:80]})"
        rows = parquet.metadata.num_rows
        if entry is not None and rows != entry["rows"]:
            return f"holds {rows} rows, {MANIFEST_FILE} {entry['rows']}"
        for name, want in (("stage", stage), ("chunk", chunk)):
            if name in table.column_names:
                found_values = np.unique(table[name].to_numpy())
                if len(found_values) and (found_values != want).any():
                    return (
                        f"holds rows of {name} {found_values.tolist()[:3]}, its name "
                        f"says {want} (a chunk swapped in from elsewhere)"
                    )
        return None

    def checked_files(self) -> list[Path]:
        """The chunk files of the run, final stage last, each checked.

        With a manifest, those it lists: one missing or not matching its
        entry is a :class:`RunDirectoryError` naming it (rerunning evaluates
        it again); files it does not list are not the run's.
        """
        directory = self.folder
        if not self._manifest.exists:
            files = list(directory.glob("*.parquet"))
        else:
            files = []
            for name, entry in self._manifest.record()["chunks"].items():
                path = directory / name
                if not path.is_file():
                    raise RunDirectoryError(
                        f"{path}: listed in {MANIFEST_FILE} ({entry['rows']} rows) "
                        "but missing; rerun the command to evaluate it again"
                    )
                problem = self._problem(
                    path, path.read_bytes(), entry["stage"], entry["chunk"]
                )
                if problem is not None:
                    path.unlink()
                    raise RunDirectoryError(
                        f"{path}: {problem}; removed: rerun the command to "
                        "evaluate it again"
                    )
                files.append(path)
        return sorted(files, key=lambda p: (p.name.startswith("stage0000"), p.name))

    def read(
        self,
        path: Path,
        columns: Sequence[str] | None = None,
        data: bytes | None = None,
    ) -> pa.Table:
        """A chunk file, its left-out columns drawn again if ``columns`` wants them."""
        table = pq.read_table(path if data is None else pa.BufferReader(data))
        meta = chunk_meta(table.schema)
        if meta is None:
            return table
        left_out = meta.get("columns")
        if columns is not None and not set(columns) & set(left_out or ()):
            return table
        filled = self.regenerator().fill(table, left_out, {chunk_key(path): meta})
        return filled.replace_schema_metadata(None)

    def regenerator(self) -> Regenerator:
        """What draws left-out columns again (a run opened with its base)."""
        if self._regenerator is None:
            raise RunDirectoryError(
                f"{self.folder.parent} stores its large blocks of X as a seed and a "
                f"proposal ({PROPOSALS_FILE}): open it with its base distribution "
                "(RunDirectory(..., base=...)) to draw them again"
            )
        return self._regenerator

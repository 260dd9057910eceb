"""The run directory: everything a run leaves behind, written so nothing is lost.

::

    DIR/
      config.json      resolved scenario and options; a different run is refused
      chunks/          one Parquet file per evaluated chunk while the run goes on
      checkpoint.json  the estimator's state and steps after its latest step
      proposals.json   each stage's proposal, to draw its large blocks again
      samples.parquet  every rollout of every stage, once the run is complete
      summary.json     estimates, intervals, ESS, timing, versions (SUMMARY_SCHEMA)
      manifest.json    each record's SHA-256 (avrisk.pipeline.manifest)
      .lock            held by the process running in DIR (avrisk.pipeline.lock)

Every file is written to a temporary name and renamed into place, so a run
killed at any moment (even ``kill -9``) leaves only whole files. Rerunning the
same command replays the recorded chunks (bit-identical numbers, see
:mod:`avrisk.rare.stages`) and evaluates only what is missing.

Given the run's base distribution, a run directory leaves the columns of its
large blocks (a learned driver's 404-d ``xi``) out of the chunks it drew fresh
and draws them again, checked, when they are read
(:mod:`avrisk.pipeline.regenerate`); ``store_full`` keeps every column.

Every chunk, the samples table and the summary are checked against the
digests of ``manifest.json`` when read (:mod:`avrisk.pipeline.manifest`): a
damaged or swapped chunk is named and evaluated again, a damaged summary or
samples table is named and refused. A digest is no defence against a forger
who rewrites the manifest too; it defends against damage and accidental
swaps. Directories made before the manifest existed are read unverified.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from avrisk.pipeline.files import (
    json_text,
    parquet_bytes,
    write_atomic,
    write_json,
)
from avrisk.pipeline.manifest import (
    MANIFEST_FILE,
    Manifest,
    RecordIntegrityWarning,
    digest,
    file_digest,
)
from avrisk.pipeline.regenerate import (
    META_KEY,
    PROPOSALS_FILE,
    RegenerationError,
    Regenerator,
    chunk_meta,
    large_block_columns,
)
from avrisk.rare import ExponentialFamily, Product, StageBatch
from avrisk.rare.problem import FINAL_STAGE

SUMMARY_SCHEMA = "avrisk.summary/1"
CONFIG_FILE = "config.json"
SUMMARY_FILE = "summary.json"
SAMPLES_FILE = "samples.parquet"
CHECKPOINT_FILE = "checkpoint.json"
CHUNKS_DIR = "chunks"
LOCK_FILE = ".lock"

#: Columns of the samples table besides the scenario parameters and extras.
BOOKKEEPING = ("phase", "stage", "iteration", "chunk", "sample_id", "seed")
DENSITIES = ("log_p0", "log_p_proposal", "log_weight", "weight", "f")

#: Disk a stored parameter takes per rollout in a samples table [B]: a float64
#: draw does not compress, and Parquet's dictionary encoding adds an index to
#: its 8 bytes; a float32-rounded one (a learned driver's ``xi``) takes 4 and
#: its index (measured on ``highway_default``'s stored ``xi``).
PARAM_ROW_BYTES, FLOAT32_PARAM_ROW_BYTES = 9.5, 5.0
#: Disk the other columns take per rollout (bookkeeping, densities, ``f`` and
#: a simulator's outcomes) [B]: with ``highway_idm``'s 24 parameters, 272 B a
#: rollout (:func:`marginal_row_bytes` of a naive run's samples table).
OTHER_ROW_BYTES = 45


class RunDirectoryError(ValueError):
    """The output directory cannot be used for this run (says why and what to do)."""


class RunDirectory:
    """A run's output directory.

    Parameters
    ----------
    path : path-like
        The directory (created by :meth:`claim`).
    param_names : sequence of str
        Names of the ``D`` coordinates of ``X`` (Parquet column names).
    units : mapping of str to str, optional
        Unit of each parameter (and of ``f``), recorded as field metadata.
    base : ExponentialFamily, optional
        The run's ``P0``: with it, chunks drawn fresh are stored without the
        columns of its large blocks, and such columns are drawn again when
        read (:mod:`avrisk.pipeline.regenerate`); without it every column is
        stored, and a directory that left some out cannot be read.
    store_full : bool, default=False
        Store every column even with ``base`` (samples.parquet then holds
        them all, drawn again where a chunk had left them out).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        param_names: Sequence[str],
        units: Mapping[str, str] | None = None,
        *,
        base: ExponentialFamily | None = None,
        store_full: bool = False,
    ) -> None:
        self.path = Path(path)
        self.store_full = store_full
        self.units = dict(units or {})
        self.param_names = list(param_names)
        if len(set(self.param_names)) != len(self.param_names):
            raise ValueError("parameter names must be unique")
        clash = set(self.param_names) & set(BOOKKEEPING + DENSITIES)
        if clash:
            raise ValueError(
                f"parameter names clash with table columns: {sorted(clash)}"
            )
        self._regenerator = (
            None if base is None else Regenerator(self.path, base, self.param_names)
        )
        self._manifest = Manifest(self.path)
        self._warned_unverified = False
        self._verified: dict[str, tuple[int, int]] = {}

    # -- lifecycle -----------------------------------------------------------------

    def claim(self, config: dict[str, Any]) -> None:
        """Create the directory for ``config``, or check that it holds the same run.

        A top-level key of ``config`` that the recorded configuration lacks
        (a run recorded by an older avrisk, before that key existed) is not a
        difference: such a run resumes, unchecked on that key.

        Raises
        ------
        RunDirectoryError
            If the directory holds a different run, or other files
            (:meth:`refuse_foreign`), or an unfinished run whose ``chunks/``
            folder (what it recorded) is gone.
        """
        config = json.loads(json.dumps(config))  # normalise tuples, keys
        config_path = self.path / CONFIG_FILE
        self.refuse_foreign()
        if config_path.is_file():
            previous = json.loads(config_path.read_text())
            config = {k: v for k, v in config.items() if k in previous}
            if previous != config:
                changed = sorted(_diff_keys(previous, config))
                raise RunDirectoryError(
                    f"{self.path} holds a different run (differs in: "
                    f"{', '.join(changed)}); choose another output directory "
                    "or delete this one"
                )
            if not self.is_complete and not (self.path / CHUNKS_DIR).is_dir():
                raise RunDirectoryError(
                    f"{self.path} holds an unfinished run whose {CHUNKS_DIR}/ folder, "
                    "what it recorded, is missing: restore that folder, or delete "
                    f"{self.path} to run it anew"
                )
            return
        (self.path / CHUNKS_DIR).mkdir(parents=True, exist_ok=True)
        self._manifest.create()  # before config.json: a new run is always verified
        write_json(config_path, config)

    def refuse_foreign(self) -> None:
        """Refuse an existing directory that holds files but no avrisk run.

        A run checks this before it takes the directory's lock, so that a
        folder of the user's is left exactly as it was found (no lock file).

        Raises
        ------
        RunDirectoryError
            If the directory has files besides the lock and the manifest and
            no ``config.json``.
        """
        if not self.path.is_dir() or (self.path / CONFIG_FILE).is_file():
            return
        ours = (LOCK_FILE, MANIFEST_FILE)
        if any(p.name not in ours for p in self.path.iterdir()):
            raise RunDirectoryError(
                f"{self.path} exists and is not an avrisk run directory "
                f"(no {CONFIG_FILE}); choose an empty or new directory"
            )

    @property
    def is_complete(self) -> bool:
        """Whether the run finished (its summary exists)."""
        return (self.path / SUMMARY_FILE).is_file()

    def has_recorded_chunks(self) -> bool:
        """Whether any chunk has been recorded (something to resume from)."""
        chunks = self.path / CHUNKS_DIR
        return chunks.is_dir() and any(chunks.glob("*.parquet"))

    def has_failed_samples(self) -> bool:
        """Whether a complete run counted rollouts that failed to evaluate."""
        estimate = self.summary()["estimate"]
        return any(g.get("n_failed") for g in estimate["by_gamma"])

    def reopen(self) -> None:
        """Turn a complete run back into recorded chunks, to evaluate again.

        The samples table is split into its chunk files (the same rows a
        resumed run replays, left-out columns still left out), then it and
        the summary are removed: the next run evaluates the chunks with
        failed rollouts again and finishes anew.
        """
        path = self.path / SAMPLES_FILE
        self._check_final(SAMPLES_FILE)
        table = pq.read_table(path)
        _, left_out = _table_meta(table.schema)
        keys = np.column_stack([table["stage"].to_numpy(), table["chunk"].to_numpy()])
        (self.path / CHUNKS_DIR).mkdir(exist_ok=True)
        for stage, chunk in np.unique(keys, axis=0):
            rows = table.filter(pa.array((keys == (stage, chunk)).all(axis=1)))
            meta = left_out.get((int(stage), int(chunk)))
            if meta is not None:
                rows = _leaving_out(rows, meta)
            self._write_chunk(rows, int(stage), int(chunk))
        (self.path / SUMMARY_FILE).unlink()  # first: the run is no longer complete
        if self._manifest.exists:
            self._manifest.set_entries(samples=None, summary=None)
        path.unlink()

    def discard(self) -> None:
        """Remove the directory (a run that failed before recording anything)."""
        shutil.rmtree(self.path, ignore_errors=True)

    # -- chunks: record and replay ---------------------------------------------

    def final_stage(self, columns: Sequence[str]) -> pa.Table:
        """Columns of the final stage's recorded chunks (before :meth:`finish`).

        Columns a chunk lacks (recorded by an older avrisk) are null there.
        """
        files = [
            p
            for p in self._chunk_files()
            if p.name.startswith(f"stage{FINAL_STAGE:04d}-")
        ]
        tables = []
        for path in files:
            table = self._read_chunk(path, columns)
            tables.append(
                pa.table(
                    {
                        c: table[c] if c in table.column_names else pa.nulls(len(table))
                        for c in columns
                    }
                )
            )
        return pa.concat_tables(tables, promote_options="default")

    def _chunk_path(self, stage: int, chunk: int) -> Path:
        return self.path / CHUNKS_DIR / f"stage{stage:04d}-chunk{chunk:06d}.parquet"

    def record(self, batch: StageBatch) -> pa.Table:
        """Store one evaluated chunk (atomically), large blocks left out if it can.

        The chunk is written first, then its manifest entry: a chunk that a
        kill left unlisted is evaluated again (see :meth:`cached`).

        Returns
        -------
        pyarrow.Table
            The rows as written (for :func:`marginal_row_bytes`).
        """
        table = samples_table(batch, self.param_names, self.units)
        if self._regenerator is not None and not self.store_full:
            meta = self._regenerator.leave_out(batch)
            if meta is not None:
                table = _leaving_out(table, meta)
        self._write_chunk(table, batch.stage, batch.chunk)
        return table

    def _write_chunk(self, table: pa.Table, stage: int, chunk: int) -> None:
        path = self._chunk_path(stage, chunk)
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
        path = self._chunk_path(stage, chunk)
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
        problem = self._chunk_problem(path, data, stage, chunk)
        if problem is not None:
            warnings.warn(
                f"{path}: {problem}; evaluated again",
                RecordIntegrityWarning,
                stacklevel=2,
            )
            path.unlink()
            return None
        table = self._read_chunk(path, data=data)
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
        for path in sorted((self.path / CHUNKS_DIR).glob("*.parquet")):
            if _CHUNK_NAME.fullmatch(path.name) is None:
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
            found.append((*_chunk_key(path), f, failed))
        return sorted(found, key=lambda c: (c[0] == FINAL_STAGE, c[0], c[1]))

    def _chunk_problem(
        self, path: Path, data: bytes, stage: int, chunk: int
    ) -> str | None:
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

    def _chunk_files(self) -> list[Path]:
        """The chunk files of the run, final stage last, each checked.

        With a manifest, those it lists: one missing or not matching its
        entry is a :class:`RunDirectoryError` naming it (rerunning evaluates
        it again); files it does not list are not the run's.
        """
        directory = self.path / CHUNKS_DIR
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
                problem = self._chunk_problem(
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

    def _read_chunk(
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
        filled = self._regenerate().fill(table, left_out, {_chunk_key(path): meta})
        return filled.replace_schema_metadata(None)

    def _regenerate(self) -> Regenerator:
        if self._regenerator is None:
            raise RunDirectoryError(
                f"{self.path} stores its large blocks of X as a seed and a proposal "
                f"({PROPOSALS_FILE}): open it with its base distribution "
                "(RunDirectory(..., base=...)) to draw them again"
            )
        return self._regenerator

    # -- checkpoints and the end of a run ---------------------------------------

    def checkpoint(self, record: dict[str, Any]) -> None:
        """Record the estimator's state after a step (for inspection and reports).

        ``record`` is the estimator's JSON-ready ``checkpoint(state, infos)``.
        """
        write_json(self.path / CHECKPOINT_FILE, record)

    def finish(self, summary: dict[str, Any]) -> None:
        """Gather the chunks into ``samples.parquet``, then write ``summary.json``.

        The table's schema metadata (:data:`~avrisk.pipeline.regenerate.META_KEY`)
        lists the chunks whose large blocks were left out, with their digests
        (with ``store_full``, those are drawn again and stored instead). The
        summary is written last: its presence marks a complete run.
        """
        files = self._chunk_files()  # final stage last
        metas = {_chunk_key(p): chunk_meta(pq.read_schema(p)) for p in files}
        left_out = {k: m for k, m in metas.items() if m is not None}
        target = self.path / SAMPLES_FILE
        tmp = target.with_name(f".{target.name}.tmp-{os.getpid()}")
        schema = _widest_schema(
            [self._gathered_schema(p, metas[_chunk_key(p)]) for p in files],
            self.param_names,
        )
        if schema is not None and left_out and not self.store_full:
            schema = schema.with_metadata({META_KEY: _table_meta_json(left_out)})
        writer = None
        try:
            for path in files:
                table = (
                    self._read_chunk(path) if self.store_full else pq.read_table(path)
                )
                if writer is None:
                    writer = pq.ParquetWriter(tmp, schema)
                writer.write_table(_conformed(table, schema))
            if writer is not None:
                writer.close()
                os.replace(tmp, target)
        except BaseException:
            if writer is not None:
                with contextlib.suppress(Exception):
                    writer.close()
            tmp.unlink(missing_ok=True)  # a full disk leaves no stray temporary
            raise
        summary = {"schema": SUMMARY_SCHEMA, **summary}
        text = json_text(summary)
        if not self._manifest.exists:  # an older run: verified from now on
            self._manifest.create()
            for path in files:
                stage, chunk = _chunk_key(path)
                rows = pq.read_metadata(path).num_rows
                self._manifest.add_chunk(
                    path.name, stage, chunk, rows, file_digest(path)
                )
        if self._manifest.exists:  # digests first: a summary is never unrecorded
            rows = pq.read_metadata(target).num_rows if files else 0
            self._manifest.set_entries(
                samples={"rows": rows, "sha256": file_digest(target)}
                if files
                else None,
                summary={"sha256": digest(text.encode())},
            )
        write_atomic(self.path / SUMMARY_FILE, text)
        shutil.rmtree(self.path / CHUNKS_DIR, ignore_errors=True)

    def _gathered_schema(self, path: Path, meta: dict[str, Any] | None) -> pa.Schema:
        """A chunk's schema in samples.parquet (left-out columns back if store_full)."""
        schema = pq.read_schema(path).remove_metadata()
        if meta is None or not self.store_full:
            return schema
        for name in meta["columns"]:
            schema = schema.append(pa.field(name, pa.float64()))
        return schema

    def summary(self) -> dict[str, Any]:
        """The summary of a complete run, checked against the manifest.

        Raises
        ------
        RunDirectoryError
            If it is not the summary the run wrote (its digest differs).
        """
        data = (self.path / SUMMARY_FILE).read_bytes()
        self._check_final(SUMMARY_FILE, digest(data))
        return json.loads(data)

    def record_problem(self) -> str | None:
        """Why a complete run's summary or samples table is not trusted, or None."""
        try:
            self._check_final(SUMMARY_FILE)
            if (self.path / SAMPLES_FILE).is_file() or self._manifest_entry("samples"):
                self._check_final(SAMPLES_FILE)
        except (RunDirectoryError, OSError) as exc:
            return str(exc)
        return None

    def recompute(self) -> None:
        """Make a complete run whose records do not verify ready to finish anew.

        With a sound samples table, its chunks are recorded again (replayed,
        not evaluated); otherwise it is removed too and everything evaluated
        again.
        """
        try:
            self._check_final(SAMPLES_FILE)
        except (RunDirectoryError, OSError):
            (self.path / SUMMARY_FILE).unlink(missing_ok=True)
            if self._manifest.exists:
                record = self._manifest.record()
                record["chunks"] = {}
                self._manifest.set_entries(samples=None, summary=None)
            (self.path / SAMPLES_FILE).unlink(missing_ok=True)
            (self.path / CHUNKS_DIR).mkdir(exist_ok=True)
            return
        self.reopen()

    def _manifest_entry(self, key: str) -> dict[str, Any] | None:
        return self._manifest.entry(key) if self._manifest.exists else None

    def _check_final(self, name: str, found: str | None = None) -> None:
        """Refuse ``samples.parquet`` or ``summary.json`` unless it matches its digest.

        ``found`` is its digest if already computed. Without a manifest (a
        run directory from before it existed) warn, once, that it is read
        unverified.
        """
        path = self.path / name
        if not self._manifest.exists:
            if not self._warned_unverified:
                self._warned_unverified = True
                warnings.warn(
                    f"{self.path} has no {MANIFEST_FILE} (made by an older avrisk): "
                    "its records are read unverified",
                    RecordIntegrityWarning,
                    stacklevel=3,
                )
            return
        key = "summary" if name == SUMMARY_FILE else "samples"
        entry = self._manifest.entry(key)
        rerun = "rerun the command to recompute it"
        if entry is None:
            raise RunDirectoryError(
                f"{path}: not recorded in {MANIFEST_FILE} (not written by this run); "
                f"{rerun}"
            )
        if found is None:
            stat = path.stat()
            if self._verified.get(name) == (stat.st_size, stat.st_mtime_ns):
                return
            found = file_digest(path)
        if found != entry["sha256"]:
            raise RunDirectoryError(
                f"{path}: SHA-256 {found[:16]} differs from the {entry['sha256'][:16]} "
                f"recorded in {MANIFEST_FILE} when the run finished (changed since); "
                f"{rerun}"
            )
        if name == SAMPLES_FILE:
            stat = path.stat()
            self._verified[name] = (stat.st_size, stat.st_mtime_ns)

    def config(self) -> dict[str, Any]:
        """The resolved configuration of the run."""
        return json.loads((self.path / CONFIG_FILE).read_text())

    def samples(
        self, columns: Sequence[str] | None = None, rows: Any = None
    ) -> pa.Table:
        """The samples table of a complete run, every column present.

        Left-out columns are drawn again, and checked, for the rows asked for
        only (float64; see :mod:`avrisk.pipeline.regenerate`).

        Parameters
        ----------
        columns : sequence of str, optional
            Columns to read (default: all, parameters in their order).
        rows : array_like of int, optional
            Row numbers to read (default: all), in the order given.

        Raises
        ------
        RegenerationError
            If a left-out block cannot be drawn again as recorded.
        RunDirectoryError
            If the table is not the one the run wrote (its digest differs).
        """
        path = self.path / SAMPLES_FILE
        self._check_final(SAMPLES_FILE)
        schema = pq.read_schema(path)
        names_left_out, left_out = _table_meta(schema)
        names = (
            list(columns)
            if columns is not None
            else _full_order([*schema.names, *names_left_out], self.param_names)
        )
        fill = [c for c in names if c in names_left_out]
        read = [c for c in names if c in schema.names]
        if fill:
            read = list(dict.fromkeys([*read, "stage", "chunk", "sample_id"]))
        table = pq.read_table(path, columns=read)
        if rows is not None:
            table = table.take(pa.array(np.asarray(rows, dtype=np.int64)))
        if fill:
            table = self._regenerate().fill(table, fill, left_out)
        return table.select(names)


def samples_table(
    batch: StageBatch,
    param_names: Sequence[str],
    units: Mapping[str, str] | None = None,
) -> pa.Table:
    """The rows of one evaluated chunk, in the samples-table format.

    One format for every table of rollouts avrisk writes (a run's
    ``samples.parquet``, ``avrisk simulate``'s output)::

        phase, stage, iteration, chunk, sample_id, seed, <parameters of X>,
        log_p0, log_p_proposal, log_weight, weight, f, <other outputs of f>

    Parameters
    ----------
    batch : StageBatch
    param_names : sequence of str
        Names of the columns of ``batch.x``.
    units : mapping of str to str, optional
        Units recorded as the ``unit`` metadata of the named fields.

    Returns
    -------
    pyarrow.Table
        ``len(batch.values)`` rows; a parameter is stored as float32 when that
        loses nothing (e.g. float32-rounded ``xi``).
    """
    n = len(batch.values)
    log_w = batch.log_p0 - batch.log_q
    final = batch.stage == FINAL_STAGE
    columns: dict[str, Any] = {
        "phase": pa.array(["final" if final else "search"] * n),
        "stage": np.full(n, batch.stage, dtype=np.int32),
        "iteration": np.full(n, -1 if final else batch.stage - 1, dtype=np.int32),
        "chunk": np.full(n, batch.chunk, dtype=np.int32),
        "sample_id": batch.ids,
        "seed": batch.seeds,
    }
    columns.update(
        (name, _narrowest(col))
        for name, col in zip(param_names, batch.x.T, strict=True)
    )
    with np.errstate(over="ignore"):
        weight = np.exp(log_w)
    columns.update(
        log_p0=batch.log_p0,
        log_p_proposal=batch.log_q,
        log_weight=log_w,
        weight=weight,
        f=batch.values,
    )
    columns.update(batch.extras)
    table = pa.table(columns)
    if not units:
        return table
    fields = [
        f.with_metadata({b"unit": units[f.name].encode()}) if f.name in units else f
        for f in table.schema
    ]
    return table.cast(pa.schema(fields))


def estimated_row_bytes(
    param_names: Sequence[str],
    base: ExponentialFamily | None = None,
    *,
    store_full: bool = False,
) -> float:
    """Disk a rollout will take in a run's samples, before any is written [B].

    :data:`PARAM_ROW_BYTES` for each parameter stored
    (:data:`FLOAT32_PARAM_ROW_BYTES` for the blocks of ``base`` that draw
    float32-rounded samples), plus :data:`OTHER_ROW_BYTES`. A run directory
    with ``base`` leaves its large blocks out unless ``store_full`` (see
    :class:`RunDirectory`). Compression and further outputs of ``f`` make the
    real figure differ: :func:`marginal_row_bytes` measures it on a chunk.
    """
    if base is None:
        return PARAM_ROW_BYTES * len(param_names) + OTHER_ROW_BYTES
    left_out = set() if store_full else set(large_block_columns(base, param_names))
    total, start = float(OTHER_ROW_BYTES), 0
    for block in base.blocks if isinstance(base, Product) else (base,):
        names = param_names[start : start + block.dim]
        start += block.dim
        each = (
            FLOAT32_PARAM_ROW_BYTES
            if getattr(block, "float32_samples", False)
            else PARAM_ROW_BYTES
        )
        total += each * sum(name not in left_out for name in names)
    return total


def marginal_row_bytes(table: pa.Table) -> float | None:
    """Disk one more row of ``table`` takes in a Parquet file [B]; None under 2 rows.

    The slope between the file of its first half and the file of the whole:
    the file's fixed part (schema, metadata, footer) cancels, so a chunk of a
    few rows gives what a rollout adds to a large samples table.
    """
    half = table.num_rows // 2
    if half == 0:
        return None
    whole = len(parquet_bytes(table))
    first = len(parquet_bytes(table.slice(0, half)))
    return (whole - first) / (table.num_rows - half)


def _narrowest(column: np.ndarray) -> np.ndarray:
    """``column`` as float32 if that loses nothing (e.g. float32-rounded xi)."""
    narrow = column.astype(np.float32)
    return narrow if np.array_equal(narrow, column) else column


def _widest_schema(
    schemas: Sequence[pa.Schema], param_names: Sequence[str]
) -> pa.Schema | None:
    """Every chunk's columns, float64 where any stored it, parameters in order.

    Chunks recorded by an earlier avrisk may lack columns that later chunks
    have (a run resumed across versions), chunks with left-out blocks lack
    those: such columns are null in their rows.
    """
    if not schemas:
        return None
    wide = {f.name for s in schemas for f in s if f.type == pa.float64()}
    fields: dict[str, pa.Field] = {}
    for schema in schemas:
        for f in schema:
            fields.setdefault(
                f.name, f.with_type(pa.float64()) if f.name in wide else f
            )
    order = _full_order(list(fields), param_names)
    return pa.schema([fields[name] for name in order if name in fields])


def _full_order(names: Sequence[str], param_names: Sequence[str]) -> list[str]:
    """``names`` in the samples-table order: bookkeeping, parameters, the rest."""
    present = set(names)
    params = [p for p in param_names if p in present]
    rest = [n for n in names if n not in BOOKKEEPING and n not in set(params)]
    return [n for n in names if n in BOOKKEEPING] + params + rest


_CHUNK_NAME = re.compile(r"stage(\d{4})-chunk(\d{6})\.parquet")


def _chunk_key(path: Path) -> tuple[int, int]:
    """``(stage, chunk)`` of a chunk file's name."""
    match = _CHUNK_NAME.fullmatch(path.name)
    if match is None:
        raise RunDirectoryError(f"{path}: not a chunk file name")
    return int(match[1]), int(match[2])


def _leaving_out(table: pa.Table, meta: dict[str, Any]) -> pa.Table:
    """A chunk's rows without the columns ``meta`` lists, ``meta`` in the schema."""
    present = [c for c in meta["columns"] if c in table.column_names]
    return table.drop_columns(present).replace_schema_metadata(
        {META_KEY: json.dumps(meta)}
    )


def _table_meta_json(left_out: Mapping[tuple[int, int], dict[str, Any]]) -> str:
    """samples.parquet's record: the left-out columns once, then each chunk's digest."""
    columns = next(iter(left_out.values()))["columns"]
    if any(m["columns"] != columns for m in left_out.values()):
        raise RegenerationError("the chunks of one run left out different columns")
    return json.dumps(
        {
            "columns": columns,
            "chunks": [
                [s, c, m["rows"], m["sha256"]] for (s, c), m in left_out.items()
            ],
        }
    )


def _table_meta(
    schema: pa.Schema,
) -> tuple[list[str], dict[tuple[int, int], dict[str, Any]]]:
    """Left-out columns of a samples table and ``(stage, chunk) -> chunk record``."""
    meta = chunk_meta(schema)
    if meta is None:
        return [], {}
    columns, chunks = meta.get("columns"), meta.get("chunks")
    ok = (
        isinstance(columns, list)
        and all(isinstance(c, str) for c in columns)
        and isinstance(chunks, list)
        and all(
            isinstance(c, list)
            and len(c) == 4
            and all(isinstance(v, int) for v in c[:3])
            and isinstance(c[3], str)
            for c in chunks
        )
    )
    if not ok:
        raise RegenerationError("malformed record of the samples' left-out columns")
    return columns, {
        (s, c): {"columns": columns, "rows": rows, "sha256": digest}
        for s, c, rows, digest in chunks
    }


def _conformed(table: pa.Table, schema: pa.Schema) -> pa.Table:
    """``table`` cast to ``schema``, missing columns filled with nulls."""
    columns = [
        table[f.name] if f.name in table.column_names else pa.nulls(len(table), f.type)
        for f in schema
    ]
    return pa.Table.from_arrays(columns, schema=schema.remove_metadata()).cast(schema)


def _diff_keys(a: Any, b: Any, prefix: str = "") -> set[str]:
    """Dotted paths at which two JSON values differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        out: set[str] = set()
        for key in set(a) | set(b):
            out |= _diff_keys(a.get(key), b.get(key), f"{prefix}{key}.")
        return out
    return set() if a == b else {prefix.rstrip(".") or "(root)"}

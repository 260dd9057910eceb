"""The run directory: everything a run leaves behind, written so nothing is lost.

::

    DIR/
      config.json      resolved scenario and options; a different run is refused
      chunks/          one Parquet file per evaluated chunk while the run goes on
      checkpoint.json  the estimator's state and steps after its latest step
      samples.parquet  every rollout of every stage, once the run is complete
      summary.json     estimates, intervals, ESS, timing, versions (SUMMARY_SCHEMA)
      .lock            held by the process running in DIR (avrisk.pipeline.lock)

Every file is written to a temporary name and renamed into place, so a run
killed at any moment (even ``kill -9``) leaves only whole files. Rerunning the
same command replays the recorded chunks (bit-identical numbers, see
:mod:`avrisk.rare.stages`) and evaluates only what is missing.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from avrisk.rare import StageBatch
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


class RunDirectoryError(ValueError):
    """The output directory cannot be used for this run (says why and what to do)."""


def write_atomic(path: Path, data: bytes | str) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename.

    A failure or interruption leaves no file at ``path`` (nor a stray temporary).
    """
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_parquet_atomic(table: pa.Table, path: Path) -> None:
    """Write ``table`` as Parquet to ``path``, atomically (see :func:`write_atomic`)."""
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    write_atomic(path, sink.getvalue().to_pybytes())


def write_json(path: Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    write_atomic(
        path, json.dumps(obj, indent=2, sort_keys=False, allow_nan=False) + "\n"
    )


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
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        param_names: Sequence[str],
        units: Mapping[str, str] | None = None,
    ) -> None:
        self.path = Path(path)
        self.units = dict(units or {})
        self.param_names = list(param_names)
        if len(set(self.param_names)) != len(self.param_names):
            raise ValueError("parameter names must be unique")
        clash = set(self.param_names) & set(BOOKKEEPING + DENSITIES)
        if clash:
            raise ValueError(
                f"parameter names clash with table columns: {sorted(clash)}"
            )

    # -- lifecycle -----------------------------------------------------------------

    def claim(self, config: dict[str, Any]) -> None:
        """Create the directory for ``config``, or check that it holds the same run.

        A top-level key of ``config`` that the recorded configuration lacks
        (a run recorded by an older avrisk, before that key existed) is not a
        difference: such a run resumes, unchecked on that key.

        Raises
        ------
        RunDirectoryError
            If the directory holds a different run, or other files.
        """
        config = json.loads(json.dumps(config))  # normalise tuples, keys
        config_path = self.path / CONFIG_FILE
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
            return
        if self.path.exists() and any(p.name != LOCK_FILE for p in self.path.iterdir()):
            raise RunDirectoryError(
                f"{self.path} exists and is not an avrisk run directory "
                f"(no {CONFIG_FILE}); choose an empty or new directory"
            )
        (self.path / CHUNKS_DIR).mkdir(parents=True, exist_ok=True)
        write_json(config_path, config)

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
        resumed run replays), then it and the summary are removed: the next
        run evaluates the chunks with failed rollouts again and finishes anew.
        """
        table = self.samples()
        keys = np.column_stack([table["stage"].to_numpy(), table["chunk"].to_numpy()])
        (self.path / CHUNKS_DIR).mkdir(exist_ok=True)
        for stage, chunk in np.unique(keys, axis=0):
            rows = table.filter(pa.array((keys == (stage, chunk)).all(axis=1)))
            write_parquet_atomic(rows, self._chunk_path(int(stage), int(chunk)))
        (self.path / SUMMARY_FILE).unlink()
        (self.path / SAMPLES_FILE).unlink()

    def discard(self) -> None:
        """Remove the directory (a run that failed before recording anything)."""
        shutil.rmtree(self.path, ignore_errors=True)

    # -- chunks: record and replay ---------------------------------------------

    def final_stage(self, columns: Sequence[str]) -> pa.Table:
        """Columns of the final stage's recorded chunks (before :meth:`finish`).

        Columns a chunk lacks (recorded by an older avrisk) are null there.
        """
        files = sorted((self.path / CHUNKS_DIR).glob(f"stage{FINAL_STAGE:04d}-*"))
        tables = []
        for path in files:
            table = pq.read_table(path)
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

    def record(self, batch: StageBatch) -> None:
        """Store one evaluated chunk (atomically)."""
        path = self._chunk_path(batch.stage, batch.chunk)
        write_parquet_atomic(samples_table(batch, self.param_names, self.units), path)

    def cached(self, stage: int, chunk: int) -> StageBatch | None:
        """The recorded chunk ``(stage, chunk)``, or ``None``."""
        path = self._chunk_path(stage, chunk)
        if not path.is_file():
            return None
        table = pq.read_table(path)
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

    # -- checkpoints and the end of a run ---------------------------------------

    def checkpoint(self, record: dict[str, Any]) -> None:
        """Record the estimator's state after a step (for inspection and reports).

        ``record`` is the estimator's JSON-ready ``checkpoint(state, infos)``.
        """
        write_json(self.path / CHECKPOINT_FILE, record)

    def finish(self, summary: dict[str, Any]) -> None:
        """Gather the chunks into ``samples.parquet``, then write ``summary.json``.

        The summary is written last: its presence marks a complete run.
        """
        files = sorted(
            (self.path / CHUNKS_DIR).glob("*.parquet"),
            key=lambda p: (p.name.startswith("stage0000"), p.name),  # final stage last
        )
        target = self.path / SAMPLES_FILE
        tmp = target.with_name(f".{target.name}.tmp-{os.getpid()}")
        schema = _widest_schema([pq.read_schema(path) for path in files])
        writer = None
        try:
            for path in files:
                table = pq.read_table(path)
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
        write_json(self.path / SUMMARY_FILE, summary)
        shutil.rmtree(self.path / CHUNKS_DIR, ignore_errors=True)

    def summary(self) -> dict[str, Any]:
        """The summary of a complete run."""
        return json.loads((self.path / SUMMARY_FILE).read_text())

    def config(self) -> dict[str, Any]:
        """The resolved configuration of the run."""
        return json.loads((self.path / CONFIG_FILE).read_text())

    def samples(self, columns: Sequence[str] | None = None) -> pa.Table:
        """The samples table of a complete run."""
        return pq.read_table(self.path / SAMPLES_FILE, columns=columns)


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


def _narrowest(column: np.ndarray) -> np.ndarray:
    """``column`` as float32 if that loses nothing (e.g. float32-rounded xi)."""
    narrow = column.astype(np.float32)
    return narrow if np.array_equal(narrow, column) else column


def _widest_schema(schemas: Sequence[pa.Schema]) -> pa.Schema | None:
    """Every chunk's columns in order of appearance, float64 where any stored it.

    Chunks recorded by an earlier avrisk may lack columns that later chunks
    have (a run resumed across versions): those are null in the older rows.
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
    return pa.schema(list(fields.values()), metadata=schemas[0].metadata)


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

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

The files' names are in :mod:`avrisk.pipeline.layout`, the chunk files'
handling in :mod:`avrisk.pipeline.chunks`, the samples table's format in
:mod:`avrisk.pipeline.samples`, the disk a rollout takes in
:mod:`avrisk.pipeline.sizing`.

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

import json
import os
import shutil
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from avrisk.pipeline.chunks import ChunkFiles
from avrisk.pipeline.files import json_text, write_atomic, write_json
from avrisk.pipeline.layout import (
    CHECKPOINT_FILE,
    CHUNKS_DIR,
    CONFIG_FILE,
    LOCK_FILE,
    SAMPLES_FILE,
    SUMMARY_FILE,
    SUMMARY_SCHEMA,
    RunDirectoryError,
    chunk_key,
)
from avrisk.pipeline.manifest import (
    MANIFEST_FILE,
    Manifest,
    RecordIntegrityWarning,
    digest,
    file_digest,
)
from avrisk.pipeline.regenerate import Regenerator
from avrisk.pipeline.samples import (
    BOOKKEEPING,
    DENSITIES,
    full_order,
    leaving_out,
    table_meta,
    write_samples,
)
from avrisk.rare import ExponentialFamily

__all__ = ["RunDirectory"]


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
        #: The chunk files: recorded, checked, replayed.
        self.chunks = ChunkFiles(
            self.path / CHUNKS_DIR,
            self.param_names,
            self.units,
            self._manifest,
            self._regenerator,
            store_full,
        )
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
        _, left_out = table_meta(table.schema)
        keys = np.column_stack([table["stage"].to_numpy(), table["chunk"].to_numpy()])
        (self.path / CHUNKS_DIR).mkdir(exist_ok=True)
        for stage, chunk in np.unique(keys, axis=0):
            rows = table.filter(pa.array((keys == (stage, chunk)).all(axis=1)))
            meta = left_out.get((int(stage), int(chunk)))
            if meta is not None:
                rows = leaving_out(rows, meta)
            self.chunks.write(rows, int(stage), int(chunk))
        (self.path / SUMMARY_FILE).unlink()  # first: the run is no longer complete
        if self._manifest.exists:
            self._manifest.set_entries(samples=None, summary=None)
        path.unlink()

    def discard(self) -> None:
        """Remove the directory (a run that failed before recording anything)."""
        shutil.rmtree(self.path, ignore_errors=True)

    # -- checkpoints and the end of a run ---------------------------------------

    def checkpoint(self, record: dict[str, Any]) -> None:
        """Record the estimator's state after a step (for inspection and reports).

        ``record`` is the estimator's JSON-ready ``checkpoint(state, infos)``.
        """
        write_json(self.path / CHECKPOINT_FILE, record)

    def finish(self, summary: dict[str, Any]) -> None:
        """Gather the chunks into ``samples.parquet``, then write ``summary.json``.

        The samples table lists the chunks whose large blocks were left out
        (:func:`~avrisk.pipeline.samples.write_samples`; with ``store_full``
        those are drawn again and stored instead). The manifest records both
        files' digests before the summary is written, last: its presence marks
        a complete run.
        """
        files = self.chunks.checked_files()  # final stage last
        target = self.path / SAMPLES_FILE
        write_samples(
            files,
            target,
            self.param_names,
            store_full=self.store_full,
            read_full=self.chunks.read,
        )
        summary = {"schema": SUMMARY_SCHEMA, **summary}
        text = json_text(summary)
        if not self._manifest.exists:  # an older run: verified from now on
            self._manifest.create()
            for path in files:
                stage, chunk = chunk_key(path)
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
        names_left_out, left_out = table_meta(schema)
        names = (
            list(columns)
            if columns is not None
            else full_order([*schema.names, *names_left_out], self.param_names)
        )
        fill = [c for c in names if c in names_left_out]
        read = [c for c in names if c in schema.names]
        if fill:
            read = list(dict.fromkeys([*read, "stage", "chunk", "sample_id"]))
        table = pq.read_table(path, columns=read)
        if rows is not None:
            table = table.take(pa.array(np.asarray(rows, dtype=np.int64)))
        if fill:
            table = self.chunks.regenerator().fill(table, fill, left_out)
        return table.select(names)


def _diff_keys(a: Any, b: Any, prefix: str = "") -> set[str]:
    """Dotted paths at which two JSON values differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        out: set[str] = set()
        for key in set(a) | set(b):
            out |= _diff_keys(a.get(key), b.get(key), f"{prefix}{key}.")
        return out
    return set() if a == b else {prefix.rstrip(".") or "(root)"}

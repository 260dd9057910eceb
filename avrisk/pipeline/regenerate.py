"""High-dimensional blocks of X that a run directory draws again instead of storing.

A chunk that a stage drew fresh from its proposal
(:class:`~avrisk.rare.stages.ChunkDraw`) is a function of the proposal, the
run seed, the stage, the chunk and its size. A run directory therefore stores
such a chunk without the columns of the base distribution's large blocks
(those of at least :data:`MIN_REGENERATED_DIM` coordinates: a learned
driver's 404-d ``xi``), records each stage's proposal once in
``proposals.json`` (:mod:`avrisk.rare.proposals`) and, per chunk, the number of
rows and the SHA-256 of the dropped block. Reading draws the chunk again and
checks the digest: a block that comes out different (another numpy drew
differently, an edited ``proposals.json``) is a :class:`RegenerationError`
naming the chunk, never silently other samples.

A chunk is stored this way only after drawing it again from its record gave
the same bits; points that are not fresh draws (MCMC moves of subset
simulation) and proposals of other kinds are stored in full.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from avrisk.pipeline.files import write_json
from avrisk.rare import ExponentialFamily, Product, StageBatch
from avrisk.rare.problem import SAMPLE_CHUNK
from avrisk.rare.proposals import Sampler, proposal_from_record, proposal_record
from avrisk.rare.stages import chunk_task
from avrisk.version import __version__

#: Blocks of the base distribution with at least this many coordinates are
#: drawn again on reading rather than stored (the 24 one-dimensional
#: initial-state blocks of a scenario are stored).
MIN_REGENERATED_DIM = 32
#: The stages' proposals and the run seed, in the run directory.
PROPOSALS_FILE = "proposals.json"
PROPOSALS_SCHEMA = "avrisk.proposals/1"
#: Parquet schema metadata key: what a chunk file (or samples table) left out.
META_KEY = b"avrisk.regenerated"


class RegenerationError(RuntimeError):
    """Dropped columns cannot be drawn again, or came out different."""


def block_digest(block: np.ndarray) -> str:
    """SHA-256 (hex) of a block of samples, shape (m, k), as little-endian float64."""
    data = np.ascontiguousarray(block, dtype="<f8")
    return hashlib.sha256(data.tobytes()).hexdigest()


def large_block_columns(
    base: ExponentialFamily, param_names: Sequence[str]
) -> list[str]:
    """Names of the columns of ``base``'s blocks of ``MIN_REGENERATED_DIM``+ dims.

    ``base`` is a :class:`~avrisk.rare.Product` (its blocks) or one block.
    """
    if base.dim != len(param_names):
        raise ValueError(
            f"the base distribution has {base.dim} coordinates, the run "
            f"{len(param_names)} parameter names"
        )
    blocks = base.blocks if isinstance(base, Product) else (base,)
    names: list[str] = []
    start = 0
    for block in blocks:
        if block.dim >= MIN_REGENERATED_DIM:
            names.extend(param_names[start : start + block.dim])
        start += block.dim
    return names


class Regenerator:
    """The large blocks of one run directory's chunks: left out, drawn again, checked.

    Parameters
    ----------
    path : Path
        The run directory (its ``proposals.json`` is read and written here).
    base : ExponentialFamily
        ``P0`` of the run (the structure every recorded proposal shares).
    param_names : sequence of str
        Names of the ``D`` columns of ``X``.
    """

    def __init__(
        self, path: Path, base: ExponentialFamily, param_names: Sequence[str]
    ) -> None:
        self.file = path / PROPOSALS_FILE
        self.base = base
        self.param_names = list(param_names)
        self.columns = large_block_columns(base, self.param_names)
        self._record: dict[str, Any] | None = None
        self._samplers: dict[int, Sampler] = {}

    # -- writing -----------------------------------------------------------------

    def leave_out(self, batch: StageBatch) -> dict[str, Any] | None:
        """What to leave out of ``batch``'s chunk file, or None to store it whole.

        Records the stage's proposal first (so no chunk file ever lacks it),
        then checks that it draws ``batch.x`` again bit for bit.

        Returns
        -------
        dict or None
            ``{"columns": [...], "rows": m, "sha256": hex}`` for the chunk's
            schema metadata (:data:`META_KEY`).
        """
        if batch.draw is None or not self.columns:
            return None
        record = proposal_record(batch.draw.proposal, self.base)
        if record is None:
            return None
        self._add_stage(batch.stage, record, batch.draw.seed)
        rows = len(batch.values)
        block = self._select(batch.x, self.columns)
        again = self._draw(batch.stage, batch.chunk, rows, self.columns)
        if not np.array_equal(block, again):
            return None
        return {"columns": self.columns, "rows": rows, "sha256": block_digest(block)}

    def _add_stage(self, stage: int, record: dict[str, Any], seed: int) -> None:
        recorded = self._proposals()
        if recorded["seed"] is None:
            recorded["seed"] = seed
        elif recorded["seed"] != seed:
            raise RegenerationError(
                f"{self.file} records seed {recorded['seed']}, the run has {seed}"
            )
        previous = recorded["stages"].get(str(stage))
        if previous is None:
            recorded["stages"][str(stage)] = json.loads(json.dumps(record))
            write_json(self.file, recorded)
        elif previous != json.loads(json.dumps(record)):
            raise RegenerationError(
                f"stage {stage}'s proposal differs from the one recorded in "
                f"{self.file}: the run does not replay as recorded"
            )

    # -- reading -----------------------------------------------------------------

    def fill(
        self, table: pa.Table, names: Sequence[str], chunks: dict[tuple[int, int], Any]
    ) -> pa.Table:
        """``table`` with the columns ``names`` drawn again where they were left out.

        Parameters
        ----------
        table : pyarrow.Table
            Rows of a samples table, with ``stage``, ``chunk`` and
            ``sample_id``; any subset, in any order.
        names : sequence of str
            Left-out columns wanted (float64 in the result).
        chunks : dict
            ``(stage, chunk) -> {"rows": m, "sha256": hex}`` of the chunks
            whose ``names`` were left out (their rows' values here are
            missing or null).

        Raises
        ------
        RegenerationError
            If a chunk comes out different from its digest.
        """
        n = table.num_rows
        stage = table["stage"].to_numpy()
        chunk = table["chunk"].to_numpy()
        ids = table["sample_id"].to_numpy()
        values = np.full((n, len(names)), np.nan)
        stored = set(table.column_names)
        for j, name in enumerate(names):
            if name in stored:  # stored in some chunks, null in others
                values[:, j] = np.asarray(
                    table[name].to_numpy(zero_copy_only=False), dtype=np.float64
                )
        keys = np.unique(np.column_stack([stage, chunk]), axis=0) if n else []
        for s, c in keys:
            meta = chunks.get((int(s), int(c)))
            if meta is None:
                continue
            rows = (stage == s) & (chunk == c)
            block = self.checked_block(int(s), int(c), meta)
            picked = block[ids[rows] - int(c) * SAMPLE_CHUNK]
            values[rows] = self._select(picked, names, among=meta["columns"])
        filled = {name: pa.array(values[:, j]) for j, name in enumerate(names)}
        kept = [c for c in table.column_names if c not in filled]
        schema = pa.schema(
            [
                *(table.schema.field(c) for c in kept),
                *(pa.field(name, pa.float64()) for name in filled),
            ],
            metadata=table.schema.metadata,
        )
        return pa.Table.from_arrays(
            [*(table[c] for c in kept), *filled.values()], schema=schema
        )

    def checked_block(self, stage: int, chunk: int, meta: Any) -> np.ndarray:
        """The left-out columns of one chunk, drawn again and checked, shape (m, k).

        ``meta`` is the chunk's :data:`META_KEY` record; ``k`` its columns.
        """
        where = f"stage {stage} chunk {chunk} of {self.file.parent}"
        columns, rows, digest = _parse_meta(meta, where)
        unknown = sorted(set(columns) - set(self.param_names))
        if unknown:
            raise RegenerationError(f"{where}: left out unknown columns {unknown[:3]}")
        block = self._draw(stage, chunk, rows, columns)
        if block_digest(block) != digest:
            drawn_with = self._proposals().get("drawn_with")
            raise RegenerationError(
                f"{where}: its columns {columns[0]}..{columns[-1]} drawn again differ "
                f"from those recorded (SHA-256); they were drawn with {drawn_with}, "
                f"now {_versions()}: read the run with those versions, or check "
                f"that {PROPOSALS_FILE} was not changed"
            )
        return block

    # -- shared ------------------------------------------------------------------

    def _draw(
        self, stage: int, chunk: int, rows: int, columns: Sequence[str]
    ) -> np.ndarray:
        seed = self._proposals()["seed"]
        x = chunk_task(self._sampler(stage), seed, stage, chunk, rows).x
        return self._select(x, columns)

    def _select(
        self, x: np.ndarray, names: Sequence[str], among: Sequence[str] | None = None
    ) -> np.ndarray:
        order = list(self.param_names if among is None else among)
        return x[:, [order.index(name) for name in names]]

    def _sampler(self, stage: int) -> Sampler:
        if stage not in self._samplers:
            record = self._proposals()["stages"].get(str(stage))
            if record is None:
                raise RegenerationError(
                    f"{self.file} records no proposal for stage {stage}: its "
                    "chunks' left-out columns cannot be drawn again"
                )
            try:
                self._samplers[stage] = proposal_from_record(record, self.base)
            except ValueError as err:
                raise RegenerationError(f"{self.file}, stage {stage}: {err}") from None
        return self._samplers[stage]

    def _proposals(self) -> dict[str, Any]:
        if self._record is None:
            self._record = (
                _read_proposals(self.file)
                if self.file.is_file()
                else {
                    "schema": PROPOSALS_SCHEMA,
                    "seed": None,
                    "drawn_with": _versions(),
                    "stages": {},
                }
            )
        return self._record


def chunk_meta(schema: pa.Schema) -> dict[str, Any] | None:
    """The :data:`META_KEY` record of a chunk file or samples table, or None."""
    raw = (schema.metadata or {}).get(META_KEY)
    if raw is None:
        return None
    try:
        meta = json.loads(raw)
    except ValueError:
        raise RegenerationError(f"unreadable {META_KEY.decode()} metadata") from None
    if not isinstance(meta, dict):
        raise RegenerationError(f"{META_KEY.decode()} metadata is not an object")
    return meta


def _parse_meta(meta: Any, where: str) -> tuple[list[str], int, str]:
    ok = (
        isinstance(meta, dict)
        and isinstance(meta.get("columns"), list)
        and meta["columns"]
        and all(isinstance(c, str) for c in meta["columns"])
        and isinstance(meta.get("rows"), int)
        and 0 < meta["rows"] <= SAMPLE_CHUNK
        and isinstance(meta.get("sha256"), str)
    )
    if not ok:
        raise RegenerationError(f"{where}: malformed record of its left-out columns")
    return meta["columns"], meta["rows"], meta["sha256"]


def _read_proposals(path: Path) -> dict[str, Any]:
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise RegenerationError(f"{path}: unreadable ({err})") from None
    ok = (
        isinstance(record, dict)
        and record.get("schema") == PROPOSALS_SCHEMA
        and isinstance(record.get("seed"), int)
        and isinstance(record.get("stages"), dict)
        and all(k.isdigit() for k in record["stages"])
    )
    if not ok:
        raise RegenerationError(f"{path}: not an {PROPOSALS_SCHEMA} record")
    return record


def _versions() -> dict[str, str]:
    return {"avrisk": __version__, "numpy": np.__version__}

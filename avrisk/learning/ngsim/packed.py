"""The packed Parquet form of the NGSIM files, and reading columns of either form.

``scripts/pack_ngsim.py`` packs each original file into a compact, lossless
zstd Parquet file (:data:`avrisk.learning.ngsim.files.NgsimFiles.packed`):

* string columns are dictionary-encoded;
* a float column whose values are decimals with ``k`` places is stored as the
  integers ``value * 10**k`` (field metadata :data:`DECIMALS_KEY`), with the
  values that are not exact decimals in a float64 column beside it (name +
  :data:`EXCEPTIONS_SUFFIX`);
* the I-80 pairs file's ``spacing`` and ``dv`` are left out when they equal
  :func:`i80_derived_columns` bit for bit.

:func:`read_column` undoes the first two on any table (the original files'
columns pass through), so the loaders of :mod:`avrisk.learning.ngsim.loaders` return
the same arrays, bit for bit, from either form.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pyarrow as pa
from numpy.typing import NDArray

from avrisk.learning.ngsim.samples import FloatArray

__all__ = [
    "DECIMALS_KEY",
    "EXCEPTIONS_SUFFIX",
    "i80_derived_columns",
    "read_column",
]

#: Field metadata key of a packed float column stored as integers: the number
#: ``k`` of decimals (value = integer / 10**k).
DECIMALS_KEY = b"avrisk.decimals"
#: Suffix of the float64 column that holds, where not null, the values of a
#: packed decimal column that are not exact decimals.
EXCEPTIONS_SUFFIX = ".float64"


def read_column(table: pa.Table, name: str, dtype: Any) -> NDArray[Any]:
    """Column ``name`` of an original or packed table as a numpy array of ``dtype``.

    Dictionary-encoded columns are decoded, and float64 columns stored as
    decimal integers turned back into their floats.

    Parameters
    ----------
    table : pyarrow.Table
    name : str
    dtype : type
        ``str``, ``np.float64`` or another numpy type to convert to.

    Returns
    -------
    ndarray of shape (N,)
    """
    col = table.column(name)
    if pa.types.is_dictionary(col.type):
        col = col.cast(pa.string())
    arr = col.to_numpy(zero_copy_only=False)
    if dtype is str:
        return np.asarray(arr, dtype=np.str_)
    if dtype is np.float64:
        return _decode_decimals(table, name, np.asarray(arr, dtype=np.float64))
    return np.asarray(arr, dtype=dtype)


def _decode_decimals(table: pa.Table, name: str, values: FloatArray) -> FloatArray:
    """Undo the packed decimal form of column ``name`` (no-op for other columns).

    The integers ``n`` (< 2**53, exact in float64) become ``n / 10**k``, the
    correctly rounded float64 of the decimal, as a CSV parser gives it.
    """
    metadata = table.schema.field(name).metadata or {}
    if DECIMALS_KEY not in metadata:
        return values
    values = values / 10.0 ** int(metadata[DECIMALS_KEY])
    exceptions = name + EXCEPTIONS_SUFFIX
    if exceptions in table.column_names:
        col = table.column(exceptions)
        exact = col.to_numpy(zero_copy_only=False)
        values = np.where(col.is_valid().to_numpy(zero_copy_only=False), exact, values)
    return values


def i80_derived_columns(feet: Mapping[str, FloatArray]) -> dict[str, FloatArray]:
    """The I-80 pairs file's ``spacing`` [ft] and ``dv`` [ft/s] from its other columns.

    The source computed them so in float64, bit for bit; the packed file omits
    them and :func:`~avrisk.learning.ngsim.loaders.load_i80_pairs` recomputes them.

    Parameters
    ----------
    feet : mapping of str to ndarray of float64
        At least the file's ``x_follower``, ``x_leader``, ``leader_length``
        [ft] and ``v_follower``, ``v_leader`` [ft/s], shape (N,).

    Returns
    -------
    dict of str to ndarray of float64, shape (N,)
        ``"spacing"`` and ``"dv"``.
    """
    return {
        "spacing": feet["x_leader"] - feet["x_follower"] - feet["leader_length"],
        "dv": feet["v_follower"] - feet["v_leader"],
    }

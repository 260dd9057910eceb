"""Where the NGSIM files are: each data set's file names and the folder holding them.

Every data set has an *original* file (as described in the original folder's
``SOURCE.md``) and a *packed* Parquet file made from it by
``scripts/pack_ngsim.py`` (:mod:`avrisk.learning.ngsim.packed`); the loaders of
:mod:`avrisk.learning.ngsim.loaders` read either and return the same arrays. The two
I-80 data sets, all that training reads, ship packed with the package in
``avrisk/data/ngsim/`` (the default folder, :func:`default_ngsim_dir`).
US-101 does not ship: set ``$AVRISK_NGSIM_DIR`` to a folder holding the
original files to use it.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import NamedTuple

__all__ = [
    "I80_LATERAL",
    "I80_PAIRS",
    "NGSIM_DIR_ENV",
    "US101_FILE",
    "NgsimFiles",
    "default_ngsim_dir",
    "ngsim_dir",
    "ngsim_file",
]

#: Environment variable naming the folder that holds the NGSIM files.
NGSIM_DIR_ENV = "AVRISK_NGSIM_DIR"


class NgsimFiles(NamedTuple):
    """File names of one data set, in the order the loaders look for them.

    Both hold the same data (the loaders return the same arrays).

    Attributes
    ----------
    original : str
        The file described in the original folder's ``SOURCE.md``.
    packed : str
        The compact Parquet file ``scripts/pack_ngsim.py`` makes from it, as
        shipped in :func:`default_ngsim_dir`.
    """

    original: str
    packed: str


#: I-80 car-following pairs
#: (:func:`~avrisk.learning.ngsim.loaders.load_i80_pairs`).
I80_PAIRS = NgsimFiles("i80_cf_pairs.csv.gz", "i80_cf_pairs.parquet")
#: I-80 16:00-16:15 pairs with lateral positions
#: (:func:`~avrisk.learning.ngsim.loaders.load_i80_lateral`).
I80_LATERAL = NgsimFiles(
    "i80_0400_0415_emd_cf_pairs.parquet", "i80_0400_0415_lateral_pairs.parquet"
)
#: US-101 trajectories (:func:`~avrisk.learning.ngsim.loaders.load_us101`); not shipped
#: with the package.
US101_FILE = "us101_vehicle_subset.csv.gz"


def default_ngsim_dir() -> Path:
    """The package folder holding the shipped (packed) NGSIM files."""
    return Path(str(resources.files("avrisk") / "data" / "ngsim"))


def ngsim_dir(path: str | Path | None = None) -> Path:
    """The folder holding the NGSIM files.

    Parameters
    ----------
    path : str or Path, optional
        Explicit folder; else ``$AVRISK_NGSIM_DIR``; else the package's folder
        (:func:`default_ngsim_dir`), which holds the I-80 data sets only.

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        If the folder does not exist.
    """
    chosen = path if path is not None else os.environ.get(NGSIM_DIR_ENV)
    folder = default_ngsim_dir() if chosen is None else Path(chosen)
    if not folder.is_dir():
        raise FileNotFoundError(f"NGSIM folder {folder} does not exist")
    return folder


def ngsim_file(names: Sequence[str], path: str | Path | None = None) -> Path:
    """The first of ``names`` that the NGSIM folder holds.

    Parameters
    ----------
    names : sequence of str
        File names, in order of preference (e.g. :data:`I80_PAIRS`).
    path : str or Path, optional
        The folder, as for :func:`ngsim_dir`.

    Returns
    -------
    Path

    Raises
    ------
    FileNotFoundError
        If the folder does not exist or holds none of ``names``; the message
        names the folder and the files.
    """
    folder = ngsim_dir(path)
    for name in names:
        if (folder / name).is_file():
            return folder / name
    raise FileNotFoundError(
        f"NGSIM folder {folder} lacks {' or '.join(names)}; pass the folder "
        f"holding it or set ${NGSIM_DIR_ENV} (see its SOURCE.md)"
    )

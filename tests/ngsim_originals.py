"""The original NGSIM files, where this machine has them (the project's machines)."""

import os
from pathlib import Path

import pytest

from avrisk.learning.ngsim.files import NGSIM_DIR_ENV

#: The original NGSIM files (see their SOURCE.md): on the project's machines
#: only, not in CI.
ORIGINAL_DIR = Path(os.environ.get(NGSIM_DIR_ENV) or "/work/shared/data/ngsim")


def original_file(name):
    """A file of :data:`ORIGINAL_DIR`; skips the test where it is absent."""
    path = ORIGINAL_DIR / name
    if not path.is_file():
        pytest.skip(
            f"original NGSIM file {path} absent (only on the project's machines; "
            f"set ${NGSIM_DIR_ENV} to the folder holding it)"
        )
    return path

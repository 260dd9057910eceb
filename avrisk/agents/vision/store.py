"""The shipped PilotNet weights (``avrisk/data/vision/pilotnet.npz``).

Written by :func:`avrisk.learning.vision.train_vision` (``avrisk train-vision``;
``avrisk/data/vision/SOURCE.md`` says how), read without pickle.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from avrisk.agents.vision.pilotnet import PilotNet

__all__ = ["PILOTNET_FILE", "default_vision_dir", "load_pilotnet"]

PILOTNET_FILE = "pilotnet.npz"


def default_vision_dir() -> Path:
    """The package folder of the shipped vision weights."""
    return Path(str(resources.files("avrisk") / "data" / "vision"))


def load_pilotnet(path: str | Path | None = None) -> PilotNet:
    """The shipped PilotNet (or the one at ``path``), float32, in eval mode.

    Parameters
    ----------
    path : str or Path, optional
        A ``.npz`` written by :meth:`PilotNet.save`; default the shipped one.

    Returns
    -------
    PilotNet
    """
    return PilotNet.load(default_vision_dir() / PILOTNET_FILE if path is None else path)

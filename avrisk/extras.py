"""The optional extras of ``pyproject.toml``, imported so that a missing one says so.

An import of an extra's module inside :func:`needs_extra` that fails because
the module is not installed raises :class:`MissingExtraError`, whose message
names what needed it and the ``pip install`` that provides it, instead of a
bare ``No module named 'msgpack'``::

    with needs_extra("gymnasium", "avrisk.gym"):
        import gymnasium

This module is a leaf (it imports nothing of avrisk).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["EXTRAS", "MissingExtraError", "needs_extra"]

#: Each extra's top-level modules, and its packages as a user knows them.
EXTRAS = {
    "external": (("zmq", "msgpack"), "pyzmq and msgpack"),
    "gymnasium": (("gymnasium",), "Gymnasium"),
    "ray": (("ray",), "Ray"),
}


class MissingExtraError(ImportError):
    """An optional dependency is not installed; the message says how to install it."""


@contextmanager
def needs_extra(extra: str, needed_by: str) -> Iterator[None]:
    """A failed import of a module of ``extra`` in the block: a MissingExtraError.

    Parameters
    ----------
    extra : str
        A key of :data:`EXTRAS` (an extra of ``pyproject.toml``).
    needed_by : str
        What needs it, for the message: ``"the external ego"``.

    Raises
    ------
    MissingExtraError
        ``"the external ego needs pyzmq and msgpack: pip install
        'avrisk[external]'"``, for a module of ``extra`` that is not installed
        (or blocked by ``None`` in ``sys.modules``); any other failed import
        propagates as it is.

    Examples
    --------
    >>> with needs_extra("ray", "a job"):
    ...     raise ModuleNotFoundError("No module named 'ray'", name="ray")
    Traceback (most recent call last):
    avrisk.extras.MissingExtraError: a job needs Ray: pip install 'avrisk[ray]'
    """
    modules, packages = EXTRAS[extra]
    try:
        yield
    except ModuleNotFoundError as err:
        if (err.name or "").partition(".")[0] not in modules:
            raise
        raise MissingExtraError(
            f"{needed_by} needs {packages}: pip install 'avrisk[{extra}]'",
            name=err.name,
        ) from err

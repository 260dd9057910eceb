"""The external-ego protocol, version 1: messages and their checked parsing.

Every message is one msgpack map with a ``"type"`` (see ``docs/ego-protocol.md``
for the whole protocol). Arrays travel as maps ``{"dtype", "shape", "data"}``:
``dtype`` one of :data:`DTYPES` (little-endian), ``shape`` a list of ints and
``data`` the C-ordered bytes. Both ends parse what they receive as untrusted:
the size is checked before decoding, msgpack decodes plain data only (no
pickle, no extension types), and every array's dtype, shape and byte count
are checked before a numpy view is made of it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from avrisk.agents.external.params import DEFAULT_MAX_MESSAGE_BYTES
from avrisk.extras import needs_extra

with needs_extra("external", "the external ego"):
    import msgpack

__all__ = [
    "DEFAULT_MAX_MESSAGE_BYTES",
    "DTYPES",
    "PROTOCOL_VERSION",
    "ProtocolError",
    "decode",
    "encode",
    "pack_array",
    "unpack_array",
]

#: The protocol version both ends state in their handshake.
PROTOCOL_VERSION = 1
#: Wire dtype codes and their numpy types (all little-endian).
DTYPES = {"f4": "<f4", "f8": "<f8", "i8": "<i8", "u1": "u1"}
_CODES = {np.dtype(v): k for k, v in DTYPES.items()}


class ProtocolError(ValueError):
    """A message that breaks the protocol (the text says how)."""


def pack_array(array: np.ndarray) -> dict[str, Any]:
    """``array`` as a wire array ``{"dtype", "shape", "data"}``.

    Examples
    --------
    >>> pack_array(np.array([1.5, 2.0], dtype=np.float32))["shape"]
    [2]
    """
    a = np.asarray(array)
    if a.dtype == np.bool_:
        a = a.astype(np.uint8)
    code = _CODES.get(
        a.dtype.newbyteorder("<") if a.dtype.byteorder == ">" else a.dtype
    )
    if code is None:
        raise ProtocolError(f"no wire dtype for {a.dtype}; use one of {list(DTYPES)}")
    data = np.ascontiguousarray(a, dtype=DTYPES[code]).tobytes()
    return {"dtype": code, "shape": list(a.shape), "data": data}


def unpack_array(
    obj: Any, name: str, *, dtypes: tuple[str, ...], shape: tuple[int, ...]
) -> np.ndarray:
    """A wire array, checked: one of ``dtypes``, exactly ``shape``.

    Returns
    -------
    ndarray
        A read-only view of the message's bytes, of shape ``shape``.

    Raises
    ------
    ProtocolError
        Naming ``name``, for anything but a well-formed array as expected.

    Examples
    --------
    >>> wire = pack_array(np.zeros(3))
    >>> unpack_array(wire, "accel", dtypes=("f8",), shape=(3,)).tolist()
    [0.0, 0.0, 0.0]
    >>> try:
    ...     unpack_array(wire, "accel", dtypes=("f8",), shape=(4,))
    ... except ProtocolError as err:
    ...     print(err)
    accel: shape [3], expected [4]
    """
    if not isinstance(obj, Mapping) or set(obj) != {"dtype", "shape", "data"}:
        raise ProtocolError(f"{name}: not an array map {{dtype, shape, data}}")
    code, dims, data = obj["dtype"], obj["shape"], obj["data"]
    if code not in dtypes:
        raise ProtocolError(f"{name}: dtype {code!r}, expected one of {list(dtypes)}")
    if not isinstance(dims, list) or not all(
        isinstance(d, int) and not isinstance(d, bool) and d >= 0 for d in dims
    ):
        raise ProtocolError(f"{name}: shape must be a list of non-negative ints")
    if tuple(dims) != tuple(shape):
        raise ProtocolError(f"{name}: shape {dims}, expected {list(shape)}")
    dtype = np.dtype(DTYPES[code])
    if not isinstance(data, bytes) or len(data) != math.prod(shape) * dtype.itemsize:
        raise ProtocolError(f"{name}: data is not {math.prod(shape)} {code} values")
    return np.frombuffer(data, dtype=dtype).reshape(shape)


def encode(message: Mapping[str, Any]) -> bytes:
    """One message as msgpack bytes (arrays already packed)."""
    return msgpack.packb(message, use_bin_type=True)


def decode(raw: bytes, max_bytes: int) -> dict[str, Any]:
    """A received message, checked to be a map with a string ``type``.

    Raises
    ------
    ProtocolError
        If it is over ``max_bytes``, not msgpack, or not such a map.

    Examples
    --------
    >>> decode(encode({"type": "hello", "protocol": 1}), 1024)["protocol"]
    1
    >>> try:
    ...     decode(bytes([0xC1]), 1024)
    ... except ProtocolError as err:
    ...     print(err)
    not a msgpack message (FormatError)
    """
    if len(raw) > max_bytes:
        raise ProtocolError(f"message of {len(raw)} bytes, over the {max_bytes} limit")
    try:
        message = msgpack.unpackb(
            raw, raw=False, strict_map_key=True, ext_hook=_no_extension
        )
    except (ValueError, msgpack.UnpackException) as err:
        raise ProtocolError(
            f"not a msgpack message ({type(err).__name__}{_detail(err)})"
        ) from None
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        raise ProtocolError("not a map with a string 'type'")
    return message


def _no_extension(code: int, data: bytes) -> Any:
    raise ValueError(f"msgpack extension type {code} is not part of the protocol")


def _detail(err: Exception) -> str:
    return f": {err}" if str(err) else ""

"""The validated ``params`` of ``ego: {policy: external}`` (no optional imports)."""

from __future__ import annotations

import ipaddress
from urllib.parse import urlsplit

from pydantic import BaseModel, ConfigDict, Field, model_validator

__all__ = [
    "DEFAULT_ADDRESS",
    "DEFAULT_MAX_MESSAGE_BYTES",
    "ExternalParams",
    "is_loopback",
]

DEFAULT_ADDRESS = "tcp://127.0.0.1:5555"
#: Largest message either end accepts by default [bytes] (64 MiB).
DEFAULT_MAX_MESSAGE_BYTES = 64 * 2**20


def is_loopback(address: str) -> bool:
    """Whether a ZeroMQ address stays on this machine (``ipc://`` or loopback TCP).

    Examples
    --------
    >>> is_loopback("tcp://127.0.0.1:5555"), is_loopback("tcp://[::1]:5555")
    (True, True)
    >>> is_loopback("tcp://10.0.0.7:5555"), is_loopback("ipc:///tmp/av.sock")
    (False, True)
    """
    parts = urlsplit(address)
    if parts.scheme == "ipc":
        return True
    if parts.scheme != "tcp" or parts.hostname is None:
        return False
    if parts.hostname == "localhost":
        return True
    try:
        return ipaddress.ip_address(parts.hostname).is_loopback
    except ValueError:
        return False


class ExternalParams(BaseModel):
    """Where the AV process is and how long to wait for it.

    Attributes
    ----------
    address : str, default="tcp://127.0.0.1:5555"
        ZeroMQ address the AV process binds (avrisk connects).
    timeout_s : float, default=2.0
        Longest wait for any reply [s]; past it the batch's running rollouts fail.
    max_message_bytes : int, default=64 MiB
        Largest request sent and reply accepted [bytes].
    allow_remote : bool, default=False
        Whether ``address`` may leave this machine (the protocol is
        unencrypted): loopback TCP or ``ipc://`` otherwise.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    address: str = DEFAULT_ADDRESS
    timeout_s: float = Field(2.0, gt=0)
    max_message_bytes: int = Field(DEFAULT_MAX_MESSAGE_BYTES, ge=1024)
    allow_remote: bool = False

    @model_validator(mode="after")
    def _loopback_unless_allowed(self) -> ExternalParams:
        if not self.allow_remote and not is_loopback(self.address):
            raise ValueError(
                f"address {self.address!r} leaves this machine and the protocol is "
                "unencrypted: set allow_remote: true to allow it"
            )
        return self

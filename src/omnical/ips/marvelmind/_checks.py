"""Shared checks and constants of the record modules (private)."""

from __future__ import annotations

from omnical.errors import ProtocolError
from omnical.ips.marvelmind.codes import REALTIME_CODES, DataCode, code_label

MILLI = 1000.0
"""mm per m, ms per s, mV per V."""


class Timestamped:
    """``is_realtime`` and ``timestamp_s`` of a record with a ``code`` and a ``timestamp_ms``."""

    __slots__ = ()
    code: DataCode
    timestamp_ms: int

    @property
    def is_realtime(self) -> bool:
        """True for a real-time code (0x008x), whose timestamp is a Unix time in ms."""
        return self.code in REALTIME_CODES

    @property
    def timestamp_s(self) -> float:
        """Timestamp in s."""
        return self.timestamp_ms / MILLI


def require_code(record: str, code: int, allowed: frozenset[DataCode]) -> DataCode:
    """Return ``code`` as a :class:`DataCode` if it is one of ``allowed``.

    Args:
        record: the record's class name, for the message.
        code: the data code given.
        allowed: the codes the record can carry.

    Raises:
        ProtocolError: the code is not allowed for the record.
    """
    if code not in allowed:
        names = ", ".join(code_label(c) for c in sorted(allowed))
        msg = f"{record}: data code {code_label(code)} is not one of {names}"
        raise ProtocolError(msg)
    return DataCode(code)


def require_length(record: str, field: str, value: bytes | tuple[object, ...], n: int) -> None:
    """Check that a fixed-size field holds ``n`` items.

    Args:
        record: the record's class name, for the message.
        field: the field's name, for the message.
        value: the field's value.
        n: the size the wire format demands.

    Raises:
        ProtocolError: the size differs.
    """
    if len(value) != n:
        msg = f"{record}: {field} must hold {n} items, got {len(value)}"
        raise ProtocolError(msg)

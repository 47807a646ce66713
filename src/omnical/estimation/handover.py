"""A value handed over to a callee, which takes it: the caller keeps no reference to it.

CPython holds a call's arguments until it returns; a callee that :meth:`Handover.take` s a long
run's arrays from a :class:`Handover` can let them go mid-call.
"""

from __future__ import annotations

from typing import Generic, TypeVar

__all__ = ["Handover", "taken"]

T = TypeVar("T")


class Handover(Generic[T]):
    """One value, taken once by the callee it is handed to (docs/DESIGN-NOTES.md)."""

    def __init__(self, value: T) -> None:
        self._value: T | None = value

    def take(self) -> T:
        """The value; the handover holds it no more (a second take: ValueError)."""
        value, self._value = self._value, None
        if value is None:
            raise ValueError("the handed-over value was taken already")
        return value


def taken(value: T | Handover[T]) -> T:
    """``value`` itself, or what it hands over (taken)."""
    return value.take() if isinstance(value, Handover) else value

"""Liveness of the devices a moving robot depends on: how long each has sent nothing valid.

A device reports a :class:`Silence`; the driver stops the robot when a device it requires is
silent beyond its limit; :class:`GapLog` marks the silences of a device that is only recorded.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Protocol

__all__ = ["GapLog", "Silence", "Watched", "silence_detail", "wait_while_silent"]


@dataclass(frozen=True)
class Silence:
    """How long a device has sent no valid data, and how long it may while the robot moves.

    Attributes:
        device: the device and its port, as the user names it ("hedgehog on /dev/ttyACM0").
        silent_s: time since its last valid data, s (inf: none yet, or the port failed).
        limit_s: the longest silence allowed during motion, s (0 once the port failed).
        detail: what arrived meanwhile ("nothing received", "312 bytes, none valid", "port
            failed: …").
    """

    device: str
    silent_s: float
    limit_s: float
    detail: str = ""

    @property
    def exceeded(self) -> bool:
        """Silent for longer than allowed."""
        return self.silent_s > self.limit_s


class Watched(Protocol):
    """A device whose silence can be asked for at any time (from any thread)."""

    def silence(self, now_s: float) -> Silence:
        """The device's silence at ``now_s`` (its clock)."""
        ...


def silence_detail(bytes_since_valid: int, error: BaseException | None) -> str:
    """What a silent device sent meanwhile, in a few words."""
    if error is not None:
        return f"port failed: {error}"
    if bytes_since_valid > 0:
        return f"{bytes_since_valid} bytes received, none valid"
    return "nothing received"


def wait_while_silent(
    devices: Callable[[], Sequence[Watched]], clock: Callable[[], float], at_most_s: float
) -> None:
    """Wait while one of ``devices()`` is silent beyond its limit, for at most ``at_most_s``.

    Before a motion starts: this process may have stalled with the devices' data waiting
    unread, and the readers take it meanwhile. The caller's watch then judges what is left.
    """
    end = clock() + at_most_s
    while (now := clock()) < end and any(d.silence(now).exceeded for d in devices()):
        time.sleep(0.005)


@dataclass
class GapLog:
    """The silences of a device that a run records but does not depend on.

    :meth:`update` is called as the run goes; it returns a line to warn with when a gap starts
    or ends, and keeps the ``/omnical/events`` markers of both edges (JSON ``{"omnical":
    "gap", "device": …, "edge": "start"|"end", …}``) in :attr:`events`, times in the caller's
    time base.
    """

    events: list[tuple[float, str]] = field(default_factory=list)
    _since_s: float | None = None

    def update(self, silence: Silence, now_s: float) -> str | None:
        """Note ``silence`` at ``now_s``; a warning line when a gap starts or ends, else None."""
        if silence.exceeded and self._since_s is None:
            since = max(0.0, now_s - silence.silent_s)  # (a gap from before the run: its start)
            self._since_s = since
            self._mark(since, silence, "start")
            how_long = f"for {silence.silent_s:.2f} s" if math.isfinite(silence.silent_s) else "yet"
            return (
                f"{silence.device}: no valid data {how_long} ({silence.detail}): going on "
                "with odometry alone, the gap is marked in the bag"
            )
        if not silence.exceeded and self._since_s is not None:
            back = now_s - silence.silent_s
            lasted = back - self._since_s
            self._since_s = None
            self._mark(back, silence, "end")
            return f"{silence.device}: data again after a gap of {lasted:.2f} s"
        return None

    def close(self, silence: Silence, now_s: float) -> None:
        """End the run: a gap still open ends at ``now_s``."""
        if self._since_s is not None:
            self._since_s = None
            self._mark(now_s, silence, "end")

    def _mark(self, t_s: float, silence: Silence, edge: str) -> None:
        text = json.dumps(
            {"omnical": "gap", "device": silence.device, "edge": edge, "detail": silence.detail},
            separators=(",", ":"),
        )
        self.events.append((t_s, text))

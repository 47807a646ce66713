"""When status frames were measured: the firmware's period, bounded by when they arrived.

:func:`frame_times` stamps a batch of frames read together, one firmware period each
(:func:`periods_between`); arrivals only bound the stamps. Design: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["FrameTimes", "frame_times", "periods_between"]


@dataclass(frozen=True)
class FrameTimes:
    """Stamps and integration steps of a batch of frames read together.

    Attributes:
        stamps_s: each frame's stamp, strictly increasing, the last at most the arrival.
        steps_s: each frame's integration step (its stamp minus the one before; 0 after a
            silent link, when the motion meanwhile is unknown).
        skipped: the link was silent beyond ``max_gap_s`` per frame before this batch.
    """

    stamps_s: tuple[float, ...]
    steps_s: tuple[float, ...]
    skipped: bool


def periods_between(frame_ends: list[int], previous_end: int, frame_length: int) -> list[int]:
    """How many firmware periods each frame closes: 1, plus one per frame's worth of bytes
    discarded before it (a frame garbled on the wire; its motion goes to the next one)."""
    out = []
    prev = previous_end
    for end in frame_ends:
        out.append(max(1, round((end - prev) / frame_length)))
        prev = end
    return out


def frame_times(
    periods: list[int],
    arrival_s: float,
    *,
    previous_stamp_s: float,
    previous_arrival_s: float,
    period_s: float,
    max_lag_s: float,
    max_gap_s: float,
) -> FrameTimes:
    """Stamp a batch of frames that arrived together at ``arrival_s``.

    Frame i is stamped ``periods[i]`` firmware periods after the frame before it. The batch is
    then squeezed to end at the arrival if it would end later (a firmware faster than
    ``period_s``), or stretched to end ``max_lag_s`` before it if it would end earlier (a
    slower firmware, frames lost without a trace); in between, the arrival times change
    nothing. After more than ``max_gap_s`` per frame since the last arrival (or before the
    first frame), nothing is integrated and the frames are stamped back from the arrival.
    """
    n = len(periods)
    t = max(arrival_s, previous_arrival_s + 1e-6 * n)  # a stamp never repeats nor goes back
    cum = [0] * n
    total = 0
    for i, p in enumerate(periods):
        total += p
        cum[i] = total
    gap = t - previous_arrival_s
    if not gap <= max_gap_s * n:  # the first frames, or a silent link: the motion is unknown
        stamps = tuple(t - (total - c) * period_s for c in cum)
        stamps = _after(stamps, previous_stamp_s)
        return FrameTimes(stamps, (0.0,) * n, skipped=math.isfinite(gap))
    start = previous_stamp_s
    span = total * period_s
    if start + span > t:  # never after the arrival
        span = t - start
    elif t - (start + span) > max_lag_s:  # never further behind it than max_lag_s
        span = t - max_lag_s - start
    stamps = _after(tuple(start + span * c / total for c in cum), start)
    steps = tuple(b - a for a, b in zip((start, *stamps[:-1]), stamps, strict=True))
    return FrameTimes(stamps, steps, skipped=False)


def _after(stamps: tuple[float, ...], previous_s: float) -> tuple[float, ...]:
    """The stamps moved up where needed so each is later than the one before."""
    out = []
    prev = previous_s
    for s in stamps:
        prev = max(s, prev + 1e-9) if math.isfinite(prev) else s
        out.append(prev)
    return tuple(out)

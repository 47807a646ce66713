"""Replay the Marvelmind topics of a recording as the hedgehog's binary stream.

:func:`marvelmind_stream` gives the bytes a real hedgehog would send; feed them to a
:class:`~omnical.ips.marvelmind.stream.StreamReader` or a port. Packet order: docs/locate.md.
"""

from __future__ import annotations

import itertools

import numpy as np

from omnical.errors import RecordingError
from omnical.ips.marvelmind.codec import encode
from omnical.ips.marvelmind.hedgehog import HedgehogSample, beacons_record, sample_frames
from omnical.recording.recording import Recording

__all__ = ["marvelmind_stream"]

_FIX_UNAVAILABLE = 0x01
_MAX_SLOTS = 4


def marvelmind_stream(recording: Recording, *, realtime: bool = False) -> bytes:
    """The hedgehog byte stream of a recording's Marvelmind topics, frames in bag-time order.

    Args:
        recording: needs ``/hedge_pos_ang``; ``/beacon_raw_distance``, ``/hedge_quality`` and
            ``/beacons_pos_a`` are used when present.
        realtime: emit the real-time codes 0x0081/0x0084 (firmware ≥ 7.200) instead of 0x0011/0x0004.

    Raises:
        RecordingError: the recording has no ``/hedge_pos_ang``.
    """
    if not recording.has("/hedge_pos_ang"):
        msg = "recording has no /hedge_pos_ang topic to replay"
        raise RecordingError(msg)
    pos = recording.topic("/hedge_pos_ang")
    t_pos = pos.t_ns
    frames: list[tuple[int, int, bytes]] = []
    burst_of: np.ndarray = np.empty(0, dtype=np.int64)
    if recording.has("/beacon_raw_distance"):
        dist = recording.topic("/beacon_raw_distance")
        burst_of = np.searchsorted(t_pos, dist.t_ns, side="right") - 1
    quality_at: dict[int, int] = {}
    if recording.has("/hedge_quality"):
        q = recording.topic("/hedge_quality")
        q_idx = np.searchsorted(t_pos, q.t_ns, side="right") - 1
        quality_at = {
            int(i): int(v) for i, v in zip(q_idx, q["quality_percent"], strict=True) if i >= 0
        }
    starts = np.searchsorted(burst_of, np.arange(len(pos)), side="left")
    ends = np.searchsorted(burst_of, np.arange(len(pos)), side="right")
    for i in range(len(pos)):
        distances: list[tuple[int, float | None]] = []
        if burst_of.size:
            for j in range(int(starts[i]), int(ends[i])):
                distances.append((int(dist["address_beacon"][j]), float(dist["distance_m"][j])))
        unavailable = int(pos["flags"][i]) & _FIX_UNAVAILABLE
        sample = HedgehogSample(  # the recorded coordinates, a held fix's too
            timestamp_ms=int(pos["timestamp_ms"][i]),
            position_m=(float(pos["x_m"][i]), float(pos["y_m"][i]), float(pos["z_m"][i])),
            distances_m=tuple(distances[:_MAX_SLOTS]),
            quality_percent=quality_at.get(i),
            unavailable=bool(unavailable),
        )
        for k, frame in enumerate(
            sample_frames(sample, address=int(pos["address"][i]), realtime=realtime)
        ):
            frames.append((int(t_pos[i]), k, frame))
    if recording.has("/beacons_pos_a"):
        b = recording.topic("/beacons_pos_a")
        # one packet per repetition: rows sharing (almost) the same time form one map message
        groups = np.flatnonzero(np.diff(b.t_ns, prepend=b.t_ns[0] - 10**9) > 100_000_000)
        bounds = [*groups.tolist(), len(b)]
        for lo, hi in itertools.pairwise(bounds):
            beacons = {
                int(b["address"][j]): (float(b["x_m"][j]), float(b["y_m"][j]), float(b["z_m"][j]))
                for j in range(lo, hi)
            }
            frames.append((int(b.t_ns[lo]), -1, encode(beacons_record(beacons))))
    frames.sort(key=lambda f: (f[0], f[1]))
    return b"".join(f[2] for f in frames)

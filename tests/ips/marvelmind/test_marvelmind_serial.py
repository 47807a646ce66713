"""End to end through a pseudo-terminal: simulated hedgehog → pty → pyserial → StreamReader."""

from __future__ import annotations

import os
import sys
import threading
from typing import BinaryIO

import numpy as np
import pytest

from omnical.errors import RecordingError
from omnical.ips.marvelmind.codec import Record
from omnical.ips.marvelmind.hedgehog import HedgehogSample, sample_frames, sample_records
from omnical.ips.marvelmind.stream import StreamReader, open_serial

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs a POSIX pseudo-terminal")


def _samples(n: int) -> list[HedgehogSample]:
    rng = np.random.default_rng(7)
    return [
        HedgehogSample(
            timestamp_ms=62 * k,
            position_m=(float(x), float(y), 0.3),
            distances_m=((1, 2.0 + 0.01 * k), (2, None), (3, 4.5)),
            quality_percent=80 + k % 20,
            latency_ms=15,
        )
        for k, (x, y) in enumerate(rng.uniform(-3.0, 3.0, (n, 2)))
    ]


def _write_all(sink: BinaryIO, chunks: list[bytes]) -> None:
    for chunk in chunks:
        sink.write(chunk)


def test_hedgehog_frames_through_a_pty_are_all_parsed() -> None:
    leader, follower = os.openpty()
    samples = _samples(60)
    frames = [f for s in samples for f in sample_frames(s, address=4)]
    garbage = b"\xff\x47\x11\x00\x16\x00"  # a false header between every cycle
    chunks = []
    for s in samples:
        chunks.append(garbage)
        chunks.extend(sample_frames(s, address=4))
    expected = [r for s in samples for r in sample_records(s, address=4)]
    try:
        port = open_serial(os.ttyname(follower), 9600, timeout_s=2.0)
        with port, os.fdopen(leader, "wb", buffering=0, closefd=False) as hedgehog:
            writer = threading.Thread(target=_write_all, args=(hedgehog, chunks), daemon=True)
            writer.start()
            reader = StreamReader()
            received: list[Record] = []
            while len(received) < len(expected):
                data = port.read(max(1, port.in_waiting))  # what the port holds, as the driver
                assert data, "the port timed out before every record arrived"
                received += reader.feed(data)
            writer.join(timeout=10.0)
        assert not writer.is_alive()
        assert received == expected
        stats = reader.stats
        assert stats.frames_ok == len(expected) == len(frames)
        assert stats.crc_failures == len(samples)
        assert stats.bytes_framed == sum(len(f) for f in frames)
    finally:
        os.close(leader)
        os.close(follower)


def test_open_serial_names_the_missing_port() -> None:
    with pytest.raises(RecordingError, match="/nonexistent/ttyMM0"):
        open_serial("/nonexistent/ttyMM0")

"""The Wheeltec codec and the resynchronising status reader (property and fuzz tests)."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.drivers.wheeltec import (
    HEADER,
    STATUS_LENGTH,
    TAIL,
    CommandParser,
    StatusFrame,
    StatusReader,
    bcc,
    decode_command,
    decode_status,
    encode_command,
    encode_status,
)


def test_command_frames_match_the_reference_examples() -> None:
    assert encode_command(0.2, 0.0, 0.0).hex(" ") == "7b 00 00 00 c8 00 00 00 00 b3 7d"
    assert encode_command(0.0, 0.0, 0.0).hex(" ") == "7b 00 00 00 00 00 00 00 00 7b 7d"


def test_command_rounds_and_clamps() -> None:
    cmd = decode_command(encode_command(0.0009, -0.0004, 100.0))
    assert cmd is not None
    assert (cmd.vx_mmps, cmd.vy_mmps, cmd.wz_mradps) == (1, 0, 32767)
    cmd = decode_command(encode_command(-1e9, float("nan"), -0.0015))
    assert cmd is not None
    assert (cmd.vx_mmps, cmd.vy_mmps, cmd.wz_mradps) == (-32768, 0, -2)


@given(st.integers(-32768, 32767), st.integers(-32768, 32767), st.integers(-32768, 32767))
def test_command_round_trip(vx: int, vy: int, wz: int) -> None:
    cmd = decode_command(encode_command(vx / 1000, vy / 1000, wz / 1000))
    assert cmd is not None
    assert (cmd.vx_mmps, cmd.vy_mmps, cmd.wz_mradps) == (vx, vy, wz)


def _random_status(rng: random.Random) -> StatusFrame:
    return StatusFrame.from_si(
        (rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-3.0, 3.0)),
        accel_mps2=(rng.gauss(0, 1.0), rng.gauss(0, 1.0), 9.81 + rng.gauss(0, 0.5)),
        gyro_radps=(rng.gauss(0, 0.05), rng.gauss(0, 0.05), rng.uniform(-3.0, 3.0)),
        battery_v=rng.uniform(10.5, 12.6),
        stop_flag=int(rng.random() < 0.05),
    )


@given(st.integers(0, 2**32 - 1))
def test_status_round_trip(seed: int) -> None:
    status = _random_status(random.Random(seed))
    frame = encode_status(status)
    assert len(frame) == STATUS_LENGTH and frame[0] == HEADER and frame[-1] == TAIL
    assert decode_status(frame) == status


@settings(max_examples=200)
@given(st.binary(max_size=400), st.integers(1, 50))
def test_reader_never_raises_on_noise(data: bytes, chunk: int) -> None:
    reader = StatusReader()
    for i in range(0, len(data), chunk):
        reader.feed(data[i : i + chunk])
    assert reader.stats.bytes_received == len(data)


def _frame_with_checksum_7b() -> bytes:
    """A plausible frame whose battery low byte is 7D and whose checksum is 7B."""
    for vx in range(-500, 500):
        status = StatusFrame(0, vx, 0, 0, (0, 0, 16395), (0, 0, 0), 0x2E7D)  # 11.901 V
        frame = encode_status(status)
        if frame[22] == HEADER:
            return frame
    raise AssertionError("no such frame")


def test_checksum_only_reader_locks_on_a_rotated_window_ours_does_not() -> None:
    frame = _frame_with_checksum_7b()
    assert frame[21] == TAIL and frame[22] == HEADER
    stream = frame[22:] + frame * 50  # the port opened mid-frame, on the checksum byte
    vendor_like = StatusReader(limits=None).feed(stream)
    # every frame it returns is the rotated window: a wrong decode, forever
    assert len(vendor_like) >= 49
    assert all(f.stop_flag == TAIL for f in vendor_like)
    ours = StatusReader().feed(stream)
    good = decode_status(frame)
    assert ours == [good] * 50


def test_fuzz_20000_frames_with_garbage_and_corruption() -> None:
    rng = random.Random(12)
    stream = bytearray()
    good: list[StatusFrame] = []
    after_burst: set[int] = set()
    corrupted = 0
    bursts = 0
    for _i in range(20_000):
        if rng.random() < 0.02:  # a burst of garbage, often holding header and tail bytes
            n = rng.randint(1, 40)
            burst = bytes(rng.choice((HEADER, TAIL, rng.randrange(256))) for _ in range(n))
            stream += burst
            after_burst.add(len(good))
            bursts += 1
        status = _random_status(rng)
        frame = bytearray(encode_status(status))
        if rng.random() < 0.01:  # one byte replaced by another value
            k = rng.randrange(STATUS_LENGTH)
            frame[k] = (frame[k] + rng.randint(1, 255)) % 256
            corrupted += 1
            stream += frame
            continue
        good.append(status)
        stream += frame
    reader = StatusReader()
    got: list[StatusFrame] = []
    pos = 0
    while pos < len(stream):
        n = rng.randint(1, 64)
        got += reader.feed(stream[pos : pos + n])
        pos += n
    assert bursts > 300 and corrupted > 150
    # no false accepts: what came out is a subsequence of the good frames, in order
    lost: list[int] = []
    j = 0
    for k, g in enumerate(good):
        if j < len(got) and got[j] == g:
            j += 1
        else:
            lost.append(k)
    assert j == len(got), "a frame was accepted that was never sent intact"
    # at most one good frame lost per garbage burst, and only right after one
    assert set(lost) <= after_burst
    assert len(lost) <= bursts


def test_firmware_command_parser_drops_bad_frames_and_waits_for_header() -> None:
    parser = CommandParser()
    good = encode_command(0.1, -0.2, 0.3)
    bad = bytearray(good)
    bad[5] ^= 0x01
    cmds = parser.feed(b"\x00\x7d" + bytes(bad) + good + good[:4])
    assert [c.twist for c in cmds] == [(0.1, -0.2, 0.3)]
    assert parser.rejected == 1
    assert [c.twist for c in parser.feed(good[4:])] == [(0.1, -0.2, 0.3)]
    assert bcc(good[:9]) == good[9]


@pytest.mark.parametrize("field", ["stop", "speed", "battery", "accel"])
def test_implausible_frames_are_refused(field: str) -> None:
    base = {
        "stop_flag": 0,
        "vx_mmps": 100,
        "vy_mmps": 0,
        "wz_mradps": 0,
        "accel_counts": (0, 0, 16395),
        "gyro_counts": (0, 0, 0),
        "battery_mv": 12000,
    }
    change = {
        "stop": {"stop_flag": 5},
        "speed": {"vx_mmps": 20000},
        "battery": {"battery_mv": 0},
        "accel": {"accel_counts": (0, 0, 0)},
    }[field]
    frame = encode_status(StatusFrame(**{**base, **change}))  # type: ignore[arg-type]
    assert decode_status(frame) is not None
    assert StatusReader().feed(frame) == []

"""StreamReader: resynchronisation after garbage, counters, chunking."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from marvelmind_strategies import records

from omnical.errors import ProtocolError
from omnical.ips.marvelmind.codec import Record, decode, encode
from omnical.ips.marvelmind.frame import RawFrame, encode_frame
from omnical.ips.marvelmind.position import HedgePosition
from omnical.ips.marvelmind.stream import StreamReader, StreamStats

REFERENCE_0011 = bytes.fromhex(
    "ff 47 11 00 16 a0 86 01 00 d2 04 00 00 c9 fd ff ff 7a 03 00 00 02 05 00 20 19 00 03 10"
)
POSITION = decode(REFERENCE_0011)


def _feed_all(reader: StreamReader, data: bytes, chunks: list[int] | None = None) -> list[Record]:
    out: list[Record] = []
    pos = 0
    for size in chunks or []:
        out += reader.feed(data[pos : pos + size])
        pos += size
    out += reader.feed(data[pos:])
    out += reader.flush()
    return out


def _assert_bytes_add_up(stats: StreamStats) -> None:
    assert stats.bytes_received == stats.bytes_framed + stats.bytes_skipped + stats.bytes_pending


def test_clean_stream_decodes_every_frame() -> None:
    reader = StreamReader()
    frames = [REFERENCE_0011] * 3
    assert reader.feed(b"".join(frames)) == [POSITION] * 3
    stats = reader.stats
    assert stats == StreamStats(
        bytes_received=87, bytes_framed=87, bytes_skipped=0, bytes_pending=0, frames_ok=3
    )


def test_byte_by_byte_equals_all_at_once() -> None:
    data = b"\x00\xff" + REFERENCE_0011 + b"\xff\x47\x11" + REFERENCE_0011
    reader = StreamReader()
    out = [rec for byte in data for rec in reader.feed(bytes([byte]))]
    out += reader.flush()
    assert out == [POSITION, POSITION]
    assert reader.stats.bytes_skipped == 5


def test_truncated_header_in_garbage_does_not_hide_next_frame() -> None:
    reader = StreamReader()
    garbage = b"\xff\x47\x11\x00\x16\x01\x02"  # a 0x0011 header cut after two payload bytes
    assert reader.feed(garbage + REFERENCE_0011) == [POSITION]
    stats = reader.stats
    assert stats.crc_failures == 1
    assert stats.bytes_skipped == len(garbage)
    assert stats.bytes_pending == 0


def test_long_false_candidate_waits_then_flush_recovers_frame() -> None:
    reader = StreamReader()
    garbage = b"\xff\x47\x34\x12\xff"  # unknown code 0x1234 announcing 255 bytes
    assert reader.feed(garbage + REFERENCE_0011) == []
    assert reader.stats.bytes_pending == len(garbage) + len(REFERENCE_0011)
    assert reader.flush() == [POSITION]
    stats = reader.stats
    assert stats.truncated == 1
    assert stats.frames_ok == 1
    assert stats.bytes_pending == 0
    _assert_bytes_add_up(stats)


def test_long_false_candidate_resolved_by_more_bytes_without_flush() -> None:
    reader = StreamReader()
    garbage = b"\xff\x47\x34\x12\xff"
    out = reader.feed(garbage + REFERENCE_0011)
    out += reader.feed(bytes(255))
    assert out == [POSITION]
    assert reader.stats.crc_failures == 1


def test_corrupted_payload_is_a_crc_failure() -> None:
    corrupted = bytearray(REFERENCE_0011)
    corrupted[10] ^= 0x40
    reader = StreamReader()
    assert reader.feed(bytes(corrupted) + REFERENCE_0011) == [POSITION]
    stats = reader.stats
    assert (stats.crc_failures, stats.frames_ok, stats.bytes_skipped) == (1, 1, 29)


def test_wrong_length_is_counted_not_raised() -> None:
    bad = encode_frame(0x0011, bytes(23))  # CRC-valid, one byte too long
    with pytest.raises(ProtocolError, match="0x0011"):
        decode(bad)
    reader = StreamReader()
    assert reader.feed(bad + REFERENCE_0011) == [POSITION]
    stats = reader.stats
    assert stats.bad_lengths == 1
    assert stats.frames_ok == 1
    assert stats.bytes_skipped == len(bad)


def test_beacon_count_mismatch_is_counted_as_bad_length() -> None:
    bad = encode_frame(0x0012, bytes([3]) + bytes(28))  # length fits 1 + 14·2, count says 3
    reader = StreamReader()
    assert reader.feed(bad + REFERENCE_0011) == [POSITION]
    assert reader.stats.bad_lengths == 1


def test_unknown_codes_counted_and_optionally_returned() -> None:
    unknown = encode_frame(0x0999, b"xyz")
    write_request = encode_frame(0x0201, bytes(12), packet_type=0x4A)
    data = unknown + REFERENCE_0011 + write_request
    quiet = StreamReader()
    assert _feed_all(quiet, data) == [POSITION]
    assert quiet.stats.unknown_codes == 2
    assert quiet.stats.bytes_framed == len(data)
    loud = StreamReader(return_unknown=True)
    out = _feed_all(loud, data)
    assert out == [
        RawFrame(packet_type=0x47, code=0x0999, payload=b"xyz"),
        POSITION,
        RawFrame(packet_type=0x4A, code=0x0201, payload=bytes(12)),
    ]


def test_flush_clears_trailing_partial_frame() -> None:
    reader = StreamReader()
    assert reader.feed(REFERENCE_0011 + REFERENCE_0011[:10]) == [POSITION]
    assert reader.stats.bytes_pending == 10
    assert reader.flush() == []
    stats = reader.stats
    assert (stats.truncated, stats.bytes_pending, stats.bytes_skipped) == (1, 0, 10)


@settings(max_examples=60, deadline=None)
@given(st.binary(max_size=1500), st.lists(st.integers(1, 64), max_size=30))
def test_arbitrary_bytes_never_raise_and_bytes_add_up(data: bytes, chunks: list[int]) -> None:
    reader = StreamReader(return_unknown=True)
    _feed_all(reader, data, chunks)
    stats = reader.stats
    assert stats.bytes_received == len(data)
    assert stats.bytes_pending == 0
    _assert_bytes_add_up(stats)


@st.composite
def _garbage(draw: st.DrawFn) -> bytes:
    """Bytes that hold no valid frame: noise, false headers, cut or corrupted frames."""
    kind = draw(st.sampled_from(["noise", "header", "truncated", "corrupted"]))
    if kind == "noise":
        return draw(st.binary(max_size=40))
    if kind == "header":
        return b"\xff" + draw(st.sampled_from([b"\x47", b"\x4a"])) + draw(st.binary(max_size=8))
    frame = encode(draw(records))
    if kind == "truncated":
        return frame[: draw(st.integers(0, len(frame) - 1))]
    corrupted = bytearray(frame)
    index = draw(st.integers(0, len(frame) - 1))
    corrupted[index] ^= draw(st.integers(1, 255))
    return bytes(corrupted)


# derandomize: a false candidate passes the CRC with probability 2^-16; a fixed example set
# keeps the test deterministic instead of flaky once in many thousand runs.
@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    st.lists(st.tuples(_garbage(), records), max_size=10),
    _garbage(),
    st.lists(st.integers(1, 200), max_size=20),
)
def test_every_valid_frame_after_garbage_is_recovered(
    pieces: list[tuple[bytes, Record]], tail: bytes, chunks: list[int]
) -> None:
    frames = [encode(record) for _, record in pieces]
    data = b"".join(g + f for (g, _), f in zip(pieces, frames, strict=True)) + tail
    reader = StreamReader(return_unknown=True)
    out = _feed_all(reader, data, chunks)
    assert out == [record for _, record in pieces]
    stats = reader.stats
    assert stats.frames_ok + stats.unknown_codes == len(frames)
    assert stats.bytes_framed == sum(len(f) for f in frames)
    assert stats.bytes_received == len(data)
    assert stats.bytes_pending == 0
    _assert_bytes_add_up(stats)


def test_chunks_of_seven_bytes_and_reader_stats() -> None:
    data = b"noise" + REFERENCE_0011 + b"\xff\x47" + REFERENCE_0011 + REFERENCE_0011[:5]
    reader = StreamReader()
    out = [r for k in range(0, len(data), 7) for r in reader.feed(data[k : k + 7])]
    out += reader.flush()
    assert out == [POSITION, POSITION]
    assert all(isinstance(r, HedgePosition) for r in out)
    stats = reader.stats
    assert stats.frames_ok == 2
    assert stats.bytes_received == len(data)
    assert stats.bytes_skipped == 5 + 2 + 5
    assert stats.bytes_pending == 0

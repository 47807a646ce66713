"""Writer side: simulated hedgehog measurements → frames → StreamReader."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.errors import ProtocolError
from omnical.ips.marvelmind.codec import decode, encode
from omnical.ips.marvelmind.codes import DataCode
from omnical.ips.marvelmind.hedgehog import (
    HedgehogSample,
    beacons_record,
    sample_frames,
    sample_records,
)
from omnical.ips.marvelmind.position import HedgePosition, PositionFlag
from omnical.ips.marvelmind.records import BeaconPositions, Quality, RawDistances
from omnical.ips.marvelmind.stream import StreamReader


def _random_samples(rng: np.random.Generator, n: int) -> list[HedgehogSample]:
    samples = []
    for k in range(n):
        beacons = rng.choice(np.arange(1, 9), size=int(rng.integers(0, 5)), replace=False)
        distances = tuple(
            (int(b), None if rng.random() < 0.1 else float(rng.uniform(0.3, 12.0))) for b in beacons
        )
        samples.append(
            HedgehogSample(
                timestamp_ms=1000 + 62 * k,
                position_m=None if rng.random() < 0.1 else tuple(rng.uniform(-5.0, 5.0, 3)),
                distances_m=distances,
                quality_percent=None if rng.random() < 0.2 else int(rng.integers(0, 101)),
                latency_ms=int(rng.integers(0, 40)),
            )
        )
    return samples


def test_one_cycle_is_position_then_distances_then_quality() -> None:
    sample = HedgehogSample(
        timestamp_ms=5000,
        position_m=(1.2344, -0.5, 0.25),
        distances_m=((3, 2.0), (4, None)),
        quality_percent=93,
        latency_ms=21,
    )
    frames = sample_frames(sample, address=7)
    decoded = [decode(f) for f in frames]
    assert [r.code for r in decoded] == [DataCode.POSITION_MM, DataCode.DISTANCES, DataCode.QUALITY]
    position, distances, quality = decoded
    assert isinstance(position, HedgePosition)
    assert (position.x_mm, position.y_mm, position.z_mm) == (1234, -500, 250)
    assert (position.address, position.timestamp, position.latency_ms) == (7, 5000, 21)
    assert PositionFlag.TIMESTAMP_MS in position.flags
    assert PositionFlag.COORDINATES_UNAVAILABLE not in position.flags
    assert position.orientation_not_applicable
    assert isinstance(distances, RawDistances)
    assert distances.hedge_address == 7
    assert distances.distances_m == {3: 2.0}
    assert distances.items[1].not_applicable
    assert [it.is_empty for it in distances.items] == [False, False, True, True]
    assert quality == Quality(address=7, quality_percent=93)


def test_failed_fix_heading_geofence_and_realtime() -> None:
    sample = HedgehogSample(
        timestamp_ms=1_700_000_000_000,
        position_m=None,
        distances_m=((9, 1.0),),
        quality_percent=0,
        heading_rad=math.pi / 2,
        geofence_zone=3,
    )
    position, distances, quality = (
        decode(f) for f in sample_frames(sample, address=2, realtime=True)
    )
    assert isinstance(position, HedgePosition)
    assert position.code is DataCode.POSITION_MM_RT
    assert PositionFlag.COORDINATES_UNAVAILABLE in position.flags
    assert PositionFlag.OUT_OF_GEOFENCE in position.flags
    assert (position.x_mm, position.y_mm, position.z_mm) == (0, 0, 0)
    assert position.heading_rad == pytest.approx(math.pi / 2)
    assert not position.orientation_not_applicable
    assert isinstance(distances, RawDistances)
    assert distances.code is DataCode.DISTANCES_RT
    assert distances.timestamp_ms == 1_700_000_000_000
    assert isinstance(quality, Quality)
    assert quality.geofence_alarm


def test_sample_without_distances_or_quality_sends_only_position() -> None:
    sample = HedgehogSample(timestamp_ms=0, position_m=(0.0, 0.0, 0.0))
    assert [r.code for r in sample_records(sample, address=1)] == [DataCode.POSITION_MM]


def test_bad_distance_lists_raise() -> None:
    too_many = HedgehogSample(
        timestamp_ms=0, position_m=None, distances_m=tuple((b, 1.0) for b in range(1, 6))
    )
    with pytest.raises(ProtocolError, match="at most 4"):
        sample_frames(too_many, address=1)
    zero = HedgehogSample(timestamp_ms=0, position_m=None, distances_m=((0, 1.0),))
    with pytest.raises(ProtocolError, match="empty slot"):
        sample_frames(zero, address=1)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.booleans())
def test_encoded_samples_parse_back_within_a_millimetre(seed: int, realtime: bool) -> None:
    samples = _random_samples(np.random.default_rng(seed), 12)
    stream = b"".join(f for s in samples for f in sample_frames(s, address=5, realtime=realtime))
    reader = StreamReader()
    out = reader.feed(stream) + reader.flush()
    expected = [r for s in samples for r in sample_records(s, address=5, realtime=realtime)]
    assert out == expected
    assert reader.stats.bytes_framed == len(stream)
    positions = [r for r in out if isinstance(r, HedgePosition)]
    for sample, position in zip(samples, positions, strict=True):
        if sample.position_m is None:
            assert PositionFlag.COORDINATES_UNAVAILABLE in position.flags
        else:
            assert np.allclose(position.position_m, sample.position_m, atol=0.5e-3)


@pytest.mark.parametrize("code", [DataCode.BEACONS_MM, DataCode.BEACONS_CM])
def test_beacons_record_round_trips(code: DataCode) -> None:
    record = beacons_record(
        {2: (4.0, 0.0, 2.5), 1: (0.0, 0.0, 2.5), 3: (4.0, 3.004, 2.5)}, code=code
    )
    assert [b.address for b in record.beacons] == [1, 2, 3]
    back = decode(encode(record))
    assert isinstance(back, BeaconPositions)
    assert back == record
    assert back.beacons[2].position_m[1] == pytest.approx(
        3.0 if code is DataCode.BEACONS_CM else 3.004
    )

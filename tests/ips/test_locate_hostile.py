"""locate on recordings it cannot make sense of: a reason, never 100 % degenerate fixes in silence."""

from __future__ import annotations

import math

import numpy as np
import pytest

from omnical.errors import ConfigError, RecordingError
from omnical.ips.beacons import BeaconMap
from omnical.ips.from_recording import locate
from omnical.recording.recording import Recording, RecordingBuilder


def _recording() -> Recording:
    builder = RecordingBuilder()
    n = 40
    t = np.repeat(np.arange(10, dtype=np.int64) * 40_000_000, 4) + np.tile(np.arange(4), 10) * 1000
    builder.add_many(
        "/beacon_raw_distance",
        t,
        address_hedge=np.full(n, 7, dtype=np.int64),
        address_beacon=np.tile(np.array([1, 2, 3, 4], dtype=np.int64), 10),
        distance_m=np.full(n, 3.0),
    )
    return builder.build()


@pytest.mark.parametrize("sigma", [math.nan, 0.0, -1.0, 11.0])
def test_a_range_sigma_that_is_no_sigma_names_its_option(sigma: float) -> None:
    with pytest.raises(ConfigError, match=r"^--sigma-m .*: the range noise σ must be positive"):
        locate(_recording(), range_sigma_m=sigma)


@pytest.mark.parametrize("z", [math.nan, math.inf, 1e9])
def test_a_hedgehog_height_that_is_no_height_is_refused(z: float) -> None:
    with pytest.raises(ConfigError, match=r"^--hedge-z .*: the hedgehog.s height must be finite"):
        locate(_recording(), hedge_z_m=z)


def test_a_beacon_map_that_matches_none_of_the_beacons_heard_is_refused() -> None:
    other = BeaconMap(
        addresses=np.array([11, 12, 13], dtype=np.int64),
        positions_m=np.array([[0.0, 0.0, 2.0], [5.0, 0.0, 2.0], [0.0, 5.0, 2.0]]),
    )
    with pytest.raises(RecordingError, match=r"beacons in /beacon_raw_distance \(1, 2, 3, 4\)"):
        locate(_recording(), beacons=other, hedge_z_m=0.3)

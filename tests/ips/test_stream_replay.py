"""The simulated IPS as a real Marvelmind byte stream, read back by the stream reader."""

from __future__ import annotations

import numpy as np

from omnical.experiment.script import load_script
from omnical.ips.marvelmind.position import HedgePosition
from omnical.ips.marvelmind.records import BeaconPositions, Quality, RawDistances
from omnical.ips.marvelmind.stream import StreamReader
from omnical.ips.stream_replay import marvelmind_stream
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin
from omnical.twin.session import simulate_run


def test_simulated_ips_stream_decodes_to_the_recorded_numbers() -> None:
    robot = load_robot("rosy-mecanum")
    script = load_script("straight-10m", robot.limits)
    rec = simulate_run(script, robot, default_twin(robot), seed=2)
    data = marvelmind_stream(rec)
    reader = StreamReader()
    records = reader.feed(data) + reader.flush()
    stats = reader.stats
    assert stats.crc_failures == 0 and stats.bytes_skipped == 0
    positions = [r for r in records if isinstance(r, HedgePosition)]
    distances = [r for r in records if isinstance(r, RawDistances)]
    quality = [r for r in records if isinstance(r, Quality)]
    beacons = [r for r in records if isinstance(r, BeaconPositions)]
    pos = rec.topic("/hedge_pos_ang")
    assert len(positions) == len(pos)
    ok = (pos["flags"] & 1) == 0
    assert not ok.all()  # some samples without a fix, holding the last one
    xs = np.array([p.x_m for p in positions])
    np.testing.assert_allclose(xs, pos["x_m"], atol=0.0005)  # a held fix's too (was 0)
    flags = np.array([int(p.flags) for p in positions])
    np.testing.assert_array_equal(flags, pos["flags"])
    dist = rec.topic("/beacon_raw_distance")
    decoded = np.array([d for r in distances for d in r.distances_m.values()])
    np.testing.assert_allclose(decoded, dist["distance_m"], atol=0.0005)
    assert len(quality) == len(rec.topic("/hedge_quality"))
    assert len(beacons) == len(np.unique(rec.topic("/beacons_pos_a").t_ns // 10**8))

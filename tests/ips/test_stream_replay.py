"""The simulated IPS as a real Marvelmind byte stream, read back by the stream reader."""

from __future__ import annotations

import itertools

import numpy as np

from omnical.errors import RecordingError
from omnical.experiment.script import load_script
from omnical.ips.marvelmind.codec import encode
from omnical.ips.marvelmind.hedgehog import HedgehogSample, beacons_record, sample_frames
from omnical.ips.marvelmind.position import HedgePosition
from omnical.ips.marvelmind.records import BeaconPositions, Quality, RawDistances
from omnical.ips.marvelmind.stream import StreamReader
from omnical.recording.recording import Recording
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin
from omnical.twin.session import simulate_run

_FIX_UNAVAILABLE = 0x01
_MAX_SLOTS = 4


def _marvelmind_stream(recording: Recording, *, realtime: bool = False) -> bytes:
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


def test_simulated_ips_stream_decodes_to_the_recorded_numbers() -> None:
    robot = load_robot("rosy-mecanum")
    script = load_script("straight-10m", robot.limits)
    rec = simulate_run(script, robot, default_twin(robot), seed=2)
    data = _marvelmind_stream(rec)
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

"""``omnical info`` reads the travel the writer tallied instead of decoding /odom and /ground_truth,
and only where the tally is trustworthy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from omnical.bags import baginfo as baginfo_module
from omnical.bags.bag import read_bag, write_bag
from omnical.bags.baginfo import summarize_bag
from omnical.bags.recorder import BagRecorder
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.recording.summary import TRAVEL_KEY_PREFIX, StoredTravel, summarize

T0_NS = 1_700_000_000_000_000_000
_IMU_COLUMNS = (
    "gyro_x_radps",
    "gyro_y_radps",
    "gyro_z_radps",
    "acc_x_mps2",
    "acc_y_mps2",
    "acc_z_mps2",
)


def _poses(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    return {
        "x_m": np.cumsum(rng.normal(0.0, 0.01, n)),
        "y_m": np.cumsum(rng.normal(0.0, 0.01, n)),
        "yaw_rad": rng.uniform(-np.pi, np.pi, n),
        "vx_mps": rng.normal(0.0, 0.2, n),
        "vy_mps": rng.normal(0.0, 0.2, n),
        "wz_radps": rng.normal(0.0, 0.5, n),
    }


def _recording(n: int = 2000, *, nan_at: int | None = None) -> Recording:
    rng = np.random.default_rng(5)
    builder = RecordingBuilder()
    t_ns = T0_NS + np.arange(n, dtype=np.int64) * 20_000_000
    odom = _poses(rng, n)
    if nan_at is not None:
        odom["x_m"][nan_at] = np.nan
    builder.add_many("/odom", t_ns, **odom)
    builder.add_many("/ground_truth", t_ns + 5_000_000, **_poses(rng, n))
    imu = {c: rng.normal(size=n) for c in _IMU_COLUMNS}
    builder.add_many("/imu", t_ns, **imu)
    return builder.build()


def _custom(location: Path) -> dict[str, str]:
    meta = yaml.safe_load((location / "metadata.yaml").read_text())
    custom = meta["rosbag2_bagfile_information"]["custom_data"]
    assert isinstance(custom, dict)
    return custom


def _no_decode(monkeypatch: pytest.MonkeyPatch) -> list[object]:
    calls: list[object] = []

    def refuse(path: object, topics: object = None) -> Recording:
        calls.append(topics)
        return read_bag(path, topics)  # type: ignore[arg-type]

    monkeypatch.setattr(baginfo_module, "read_bag", refuse)
    return calls


def test_write_bag_states_the_travel_and_info_uses_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    recording = _recording()
    location = write_bag(recording, tmp_path / "run.mcap")
    custom = _custom(location)
    assert {TRAVEL_KEY_PREFIX + "/odom", TRAVEL_KEY_PREFIX + "/ground_truth"} <= set(custom)
    calls = _no_decode(monkeypatch)
    got = summarize_bag(location)
    assert calls == []  # nothing decoded
    assert got == summarize(recording)


def test_recorder_tally_over_many_writes_equals_the_decoded_travel(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    recording = _recording(3000)
    with BagRecorder(tmp_path / "rec.mcap", flush_period_s=0.0) as rec:
        for start in range(0, 3000, 97):  # interleaved topics, uneven pieces
            for topic in ("/imu", "/odom", "/ground_truth"):
                table = recording.topic(topic)
                part = slice(start, min(start + 97, len(table)))
                rec.write_rows(topic, table.t_ns[part], **{c: table[c][part] for c in table.names})
    calls = _no_decode(monkeypatch)
    got = summarize_bag(tmp_path / "rec.mcap")
    assert calls == []
    want = summarize(read_bag(tmp_path / "rec.mcap"))
    assert got.distance_odom_m == pytest.approx(want.distance_odom_m, rel=1e-12)
    assert got.distance_ground_truth_m == pytest.approx(want.distance_ground_truth_m, rel=1e-12)
    assert got.final_pose_odom == want.final_pose_odom
    assert got.final_pose_ground_truth == want.final_pose_ground_truth


def test_a_topic_reading_would_clean_is_not_tallied(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    recording = _recording(nan_at=700)
    location = write_bag(recording, tmp_path / "nan.mcap")
    custom = _custom(location)
    assert TRAVEL_KEY_PREFIX + "/odom" not in custom  # reading drops the NaN row
    assert TRAVEL_KEY_PREFIX + "/ground_truth" in custom
    calls = _no_decode(monkeypatch)
    got = summarize_bag(location)
    assert calls == [["/odom"]]
    assert got.distance_odom_m == summarize(read_bag(location)).distance_odom_m


def test_a_tally_that_disagrees_with_the_index_is_ignored(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    recording = _recording()
    location = write_bag(recording, tmp_path / "edited.mcap")
    meta_path = location / "metadata.yaml"
    meta = yaml.safe_load(meta_path.read_text())
    custom = meta["rosbag2_bagfile_information"]["custom_data"]
    stored = StoredTravel.from_json(custom[TRAVEL_KEY_PREFIX + "/odom"])
    assert stored is not None
    forged = StoredTravel(stored.count - 1, stored.first_ns, stored.last_ns, 1e9, (0.0, 0.0, 0.0))
    custom[TRAVEL_KEY_PREFIX + "/odom"] = forged.to_json()
    custom[TRAVEL_KEY_PREFIX + "/ground_truth"] = "{not json"
    meta_path.write_text(yaml.safe_dump(meta))
    calls = _no_decode(monkeypatch)
    got = summarize_bag(location)
    assert calls == [["/odom", "/ground_truth"]]
    assert got == summarize(recording)


@pytest.mark.parametrize(
    "text",
    ["", "[]", "{}", '{"count": 1}', "null", '{"count":"x","first_ns":0,"last_ns":0}', "1" * 2000],
)
def test_malformed_stored_travel_is_none(text: str) -> None:
    assert StoredTravel.from_json(text) is None

"""Array-valued messages: LaserScan, JointState (any topic name), MagneticField.

The bulk codec must be byte for byte rosbags' serializer (messages built as rosbags objects),
round-trip through ROS 2 and ROS 1 bags, and be readable by rosbags' AnyReader.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from recording_samples import export_csv
from rosbags.highlevel import AnyReader

from omnical.bags.bag import read_bag, write_bag
from omnical.bags.messages import decode_messages, encode_table
from omnical.bags.typestores import RosVersion, typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Recording, RecordingBuilder, Table
from omnical.recording.topics import TOPICS, MessageKind, joint_state_spec, recognise_topic

T0 = 1_700_000_000_123_456_789


def _scan(n: int = 6, beams: int = 9, intensities: int = 0) -> Table:
    rng = np.random.default_rng(3)
    ranges = rng.uniform(0.2, 5.0, (n, beams)).astype(np.float32)
    ranges[0, 1], ranges[1, 2], ranges[2, 3 % beams] = np.inf, -np.inf, np.nan
    t = T0 + np.arange(n, dtype=np.int64) * 100_000_000

    def f32(value: float) -> Any:  # LaserScan scalars are float32 on the wire
        return np.full(n, value, dtype=np.float32).astype(np.float64)

    return Table(
        t,
        {
            "angle_min_rad": f32(-np.pi),
            "angle_max_rad": f32(np.pi - 2 * np.pi / beams),
            "angle_increment_rad": f32(2 * np.pi / beams),
            "time_increment_s": f32(0.0),
            "scan_time_s": f32(0.1),
            "range_min_m": f32(0.15),
            "range_max_m": f32(12.0),
            "ranges_m": ranges,
            "intensities": rng.uniform(0, 100, (n, intensities)).astype(np.float32),
        },
    )


def _joints(n: int = 5) -> Table:
    rng = np.random.default_rng(4)
    names = np.array([["dead_wheel_x", "dead_wheel_y"]] * n, dtype=object)
    names[2] = ["left", "right"]
    return Table(
        T0 + np.arange(n, dtype=np.int64) * 10_000_000,
        {
            "name": names,
            "position_rad": rng.normal(0, 100, (n, 2)),
            "velocity_radps": rng.normal(0, 3, (n, 2)),
            "effort_nm": np.zeros((n, 0)),
        },
    )


def _mag(n: int = 4) -> Table:
    rng = np.random.default_rng(5)
    return Table(
        T0 + np.arange(n, dtype=np.int64) * 20_000_000,
        {f"mag_{c}_t": rng.normal(0, 3e-5, n) for c in "xyz"},
    )


def _rosbags_message(store: Any, kind: MessageKind, table: Table, i: int, ros: RosVersion) -> Any:
    t = store.types
    sec, nsec = divmod(int(table.t_ns[i]), 1_000_000_000)
    stamp = t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    header_type = t["std_msgs/msg/Header"]
    if kind == MessageKind.LASER_SCAN:
        header = (
            header_type(seq=i, stamp=stamp, frame_id="laser")
            if ros == 1
            else header_type(stamp=stamp, frame_id="laser")
        )
        return t["sensor_msgs/msg/LaserScan"](
            header=header,
            angle_min=float(table["angle_min_rad"][i]),
            angle_max=float(table["angle_max_rad"][i]),
            angle_increment=float(table["angle_increment_rad"][i]),
            time_increment=float(table["time_increment_s"][i]),
            scan_time=float(table["scan_time_s"][i]),
            range_min=float(table["range_min_m"][i]),
            range_max=float(table["range_max_m"][i]),
            ranges=np.asarray(table["ranges_m"][i], dtype=np.float32),
            intensities=np.asarray(table["intensities"][i], dtype=np.float32),
        )
    if kind == MessageKind.JOINT_STATE:
        header = (
            header_type(seq=i, stamp=stamp, frame_id="")
            if ros == 1
            else header_type(stamp=stamp, frame_id="")
        )
        return t["sensor_msgs/msg/JointState"](
            header=header,
            name=[str(v) for v in table["name"][i]],
            position=np.asarray(table["position_rad"][i], dtype=np.float64),
            velocity=np.asarray(table["velocity_radps"][i], dtype=np.float64),
            effort=np.asarray(table["effort_nm"][i], dtype=np.float64),
        )
    header = (
        header_type(seq=i, stamp=stamp, frame_id="imu_link")
        if ros == 1
        else header_type(stamp=stamp, frame_id="imu_link")
    )
    return t["sensor_msgs/msg/MagneticField"](
        header=header,
        magnetic_field=t["geometry_msgs/msg/Vector3"](
            x=float(table["mag_x_t"][i]), y=float(table["mag_y_t"][i]), z=float(table["mag_z_t"][i])
        ),
        magnetic_field_covariance=np.zeros(9),
    )


CASES = [
    (TOPICS["/scan"], _scan()),
    (TOPICS["/scan"], _scan(intensities=9)),
    (joint_state_spec("/wheel_ticks"), _joints()),
    (TOPICS["/dead_wheels"], _joints()),
    (TOPICS["/imu/mag"], _mag()),
]


@pytest.mark.parametrize("ros", [1, 2])
@pytest.mark.parametrize(("spec", "table"), CASES)
def test_bulk_codec_is_rosbags_byte_for_byte(spec: Any, table: Table, ros: RosVersion) -> None:
    store = typestore(ros)
    payloads = encode_table(spec, table, ros)
    serialize = store.serialize_cdr if ros == 2 else store.serialize_ros1
    for i, payload in enumerate(payloads):
        oracle = serialize(_rosbags_message(store, spec.kind, table, i, ros), spec.ros2_type)
        assert bytes(payload) == bytes(oracle)
    columns = decode_messages(
        spec.kind, spec.ros2_type, [bytes(p) for p in payloads], store, ros, "here"
    )
    for name in table.names:
        np.testing.assert_array_equal(columns[name], table[name])


def _recording() -> Recording:
    return Recording(
        {"/scan": _scan(), "/imu/mag": _mag(), "/dead_wheels": _joints(), "/wheel_ticks": _joints()}
    )


@pytest.mark.parametrize("name", ["run.mcap", "run.bag"])
def test_round_trip_and_anyreader(tmp_path: Path, name: str) -> None:
    recording = _recording()
    location = write_bag(recording, tmp_path / name)
    back = read_bag(location)
    assert set(back.topics) == set(recording.topics)
    assert back.notes == ()  # REP 117 infinities and NaN are values, not corruption
    for topic, table in recording.tables.items():
        np.testing.assert_array_equal(back.topic(topic).t_ns, table.t_ns)
        for column in table.names:
            np.testing.assert_array_equal(back.topic(topic)[column], table[column])
    assert read_bag(location, ["/wheel_ticks"]).topics == ("/wheel_ticks",)
    with AnyReader([location]) as reader:
        seen = {c.topic: c.msgtype for c in reader.connections}
        assert seen["/scan"] == "sensor_msgs/msg/LaserScan"
        assert seen["/wheel_ticks"] == "sensor_msgs/msg/JointState"
        scans = [
            reader.deserialize(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if c.topic == "/scan"
        ]
        mags = [
            reader.deserialize(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if c.topic == "/imu/mag"
        ]
        joints = [
            reader.deserialize(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if c.topic == "/dead_wheels"
        ]
    np.testing.assert_array_equal(scans[1].ranges, recording.topic("/scan")["ranges_m"][1])
    assert scans[0].header.frame_id == "laser"
    assert np.isposinf(scans[0].ranges[1]) and np.isneginf(scans[1].ranges[2])
    assert mags[2].magnetic_field.z == recording.topic("/imu/mag")["mag_z_t"][2]
    assert joints[2].name == ["left", "right"]
    np.testing.assert_array_equal(
        joints[3].position, recording.topic("/dead_wheels")["position_rad"][3]
    )


def test_changing_sequence_length_is_refused(tmp_path: Path) -> None:
    store = typestore(2)
    spec = TOPICS["/scan"]
    raws = [bytes(p) for p in encode_table(spec, _scan(3, 9), 2)]
    raws += [bytes(p) for p in encode_table(spec, _scan(3, 8), 2)]
    with pytest.raises(RecordingError, match=r"here: field ranges: message 3 holds 8 values"):
        decode_messages(spec.kind, spec.ros2_type, raws, store, 2, "here")


def test_joint_states_recognised_by_type_under_any_name() -> None:
    hit = recognise_topic("wheel_ticks", "sensor_msgs/msg/JointState")
    assert hit == ("/wheel_ticks", MessageKind.JOINT_STATE)


def test_builder_casts_names_and_csv_expands_arrays(tmp_path: Path) -> None:
    builder = RecordingBuilder()
    joints = _joints(3)
    builder.add_many("/dead_wheels", joints.t_ns, **dict(joints.columns))
    scan = _scan(3, 3)
    builder.add_many("/scan", scan.t_ns, **dict(scan.columns))
    recording = builder.build()
    assert recording.topic("/dead_wheels")["name"].shape == (3, 2)
    files = {p.name: p for p in export_csv(recording, tmp_path)}
    head = files["scan.csv"].read_text().splitlines()[0].split(",")
    assert head[-3:] == ["ranges_m.0", "ranges_m.1", "ranges_m.2"]
    assert "inf" in files["scan.csv"].read_text()
    assert files["dead_wheels.csv"].read_text().splitlines()[0].startswith("t_ns,name.0,name.1")

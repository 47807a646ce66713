"""Bulk CDR / ROS 1 codec against rosbags' own serialisers (the oracle)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from recording_samples import column_values, oracle_bytes, oracle_message, sample_recording

from omnical.bags.layout import (
    NotFixedLayoutError,
    decode_fixed,
    make_layout,
    message_leaves,
)
from omnical.bags.messages import decode_messages, encode_table
from omnical.bags.typestores import typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Table
from omnical.recording.topics import TOPICS, MessageKind


@pytest.mark.parametrize("ros", [1, 2])
@pytest.mark.parametrize("topic", list(TOPICS))
def test_bulk_encoding_matches_rosbags_byte_for_byte(topic: str, ros: int) -> None:
    rng = np.random.default_rng(7)
    table = sample_recording(rng, n=12).topic(topic)
    spec = TOPICS[topic]
    payloads = encode_table(spec, table, ros)  # type: ignore[arg-type]
    assert len(payloads) == len(table)
    for i, payload in enumerate(payloads):
        assert bytes(payload) == oracle_bytes(spec, table, i, ros)  # type: ignore[arg-type]


def test_cdr_layout_of_odometry_has_the_documented_offsets() -> None:
    store = typestore(2)
    layout = make_layout(
        message_leaves(store, "nav_msgs/msg/Odometry"),
        {"header.frame_id": b"odom", "child_frame_id": b"base_link"},
        cdr=True,
    )
    fields = layout.dtype.fields
    assert fields is not None
    # header 4 + stamp 8, "odom\0" (len 5) → 21, align 4 → 24: child len, "base_link\0" → 38,
    # align 8 → 40 (+4 header = 44) for position.x; 724 bytes in all.
    assert fields["header.frame_id#len"][1] == 12
    assert fields["child_frame_id#len"][1] == 24
    assert fields["pose.pose.position.x"][1] == 44
    assert layout.dtype.itemsize == 724


@pytest.mark.parametrize("ros", [1, 2])
def test_decode_handles_frame_ids_of_different_lengths(ros: int) -> None:
    store = typestore(ros)  # type: ignore[arg-type]
    spec = TOPICS["/odom"]
    rng = np.random.default_rng(3)
    n = 9
    table = Table(
        np.arange(n, dtype=np.int64) * 10**7 + 10**9,
        column_values(spec, n, rng),
    )
    raws = []
    for i in range(n):
        message = oracle_message(spec, table, i, ros)  # type: ignore[arg-type]
        message.header.frame_id = ["odom", "o", "a_much_longer_frame"][i % 3]
        message.child_frame_id = ["base_link", "", "base_footprint"][i % 2]
        if ros == 2:
            raws.append(bytes(store.serialize_cdr(message, spec.ros2_type)))
        else:
            raws.append(bytes(store.serialize_ros1(message, spec.ros1_type)))
    columns = decode_messages(MessageKind.ODOMETRY, spec.ros2_type, raws, store, ros, "t")  # type: ignore[arg-type]
    for name in ("x_m", "y_m", "vx_mps", "vy_mps", "wz_radps"):
        np.testing.assert_array_equal(columns[name], table[name])
    np.testing.assert_allclose(columns["yaw_rad"], table["yaw_rad"], atol=1e-12)


def test_big_endian_and_padded_cdr_messages_decode() -> None:
    store = typestore(2)
    spec = TOPICS["/beacon_raw_distance"]
    rng = np.random.default_rng(4)
    table = Table(np.arange(6, dtype=np.int64), column_values(spec, 6, rng))
    raws = [oracle_bytes(spec, table, i, 2) for i in range(6)]
    raws[1] = bytes(
        store.serialize_cdr(oracle_message(spec, table, 1, 2), spec.ros2_type, little_endian=False)
    )
    raws[2] = raws[2] + b"\x00\x00"  # trailing padding, as some DDS serialisers add
    columns = decode_messages(MessageKind.BEACON_DISTANCE, spec.ros2_type, raws, store, 2, "t")
    for name in spec.column_names:
        np.testing.assert_array_equal(columns[name], table[name])


def test_undecodable_message_raises_recording_error_with_context() -> None:
    store = typestore(2)
    with pytest.raises(RecordingError, match=r"bag\.mcap: topic /odom"):
        decode_messages(
            MessageKind.ODOMETRY,
            "nav_msgs/msg/Odometry",
            [b"\x00\x01\x00\x00\x05"],
            store,
            2,
            "bag.mcap: topic /odom",
        )


def test_sequences_of_messages_have_no_fixed_layout() -> None:
    with pytest.raises(NotFixedLayoutError, match="sequence"):
        message_leaves(typestore(2), "sensor_msgs/msg/PointCloud2")


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=40, deadline=None)
@given(
    rows=st.lists(
        st.tuples(
            st.integers(0, 255),
            st.integers(-(2**63), 2**63 - 1),
            finite,
            finite,
            finite,
            st.integers(0, 255),
            finite,
        ),
        min_size=1,
        max_size=20,
    ),
    ros=st.sampled_from([1, 2]),
)
def test_hedge_pos_ang_round_trip(
    rows: list[tuple[int, int, float, float, float, int, float]], ros: int
) -> None:
    spec = TOPICS["/hedge_pos_ang"]
    values = {
        name: np.array([r[k] for r in rows], dtype=spec.dtype_of(name))
        for k, name in enumerate(spec.column_names)
    }
    table = Table(np.arange(len(rows), dtype=np.int64), values)
    payloads = [bytes(p) for p in encode_table(spec, table, ros)]  # type: ignore[arg-type]
    msgtype = spec.ros2_type if ros == 2 else spec.ros1_type
    columns = decode_messages(spec.kind, msgtype, payloads, typestore(ros), ros, "t")  # type: ignore[arg-type]
    for name in spec.column_names:
        np.testing.assert_array_equal(columns[name], values[name])


@settings(max_examples=40, deadline=None)
@given(
    raw_strings=st.lists(
        st.binary(min_size=0, max_size=12).filter(lambda b: b"\x00" not in b),
        min_size=1,
        max_size=8,
    ),
    ros=st.sampled_from([1, 2]),
)
def test_decode_fixed_groups_any_string_lengths(raw_strings: list[bytes], ros: int) -> None:
    store = typestore(ros)  # type: ignore[arg-type]
    leaves = message_leaves(store, "sensor_msgs/msg/Imu")
    cdr = ros == 2
    raws = []
    for i, frame in enumerate(raw_strings):
        layout = make_layout(leaves, {"header.frame_id": frame}, cdr=cdr)
        array = np.zeros(1, dtype=layout.dtype)
        if cdr:
            array["_cdr_header"] = (0, 1, 0, 0)
        array["header.frame_id#len"] = len(frame) + (1 if cdr else 0)
        if frame or cdr:
            array["header.frame_id#chars"] = frame
        array["angular_velocity.z"] = float(i)
        raws.append(array.tobytes())
    fields, rejected = decode_fixed(leaves, raws, ["angular_velocity.z"], cdr=cdr)
    assert rejected.size == 0
    np.testing.assert_array_equal(fields["angular_velocity.z"], np.arange(len(raws), dtype=float))

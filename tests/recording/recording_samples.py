"""Sample recordings and a slow, obviously correct oracle: rosbags message objects."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from omnical.bags.typestores import RosVersion, typestore
from omnical.recording.recording import Recording, RecordingBuilder, Table
from omnical.recording.topics import TOPICS, TopicSpec

T0_NS = 1_700_000_000_123_456_789


def column_values(spec: TopicSpec, n: int, rng: np.random.Generator) -> dict[str, Any]:
    """Random values of every column of ``spec``, covering the dtype ranges."""
    values: dict[str, Any] = {}
    for column in spec.columns:
        if column.array:
            k = 7 if spec.name == "/scan" else 3
            if column.dtype == "object":
                values[column.name] = np.array([["fl", "front_right", "x"]] * n, dtype=object)
            elif column.name == "ranges_m":
                ranges = rng.uniform(0.1, 12.0, (n, k)).astype(np.float32)
                ranges[rng.random((n, k)) < 0.1] = np.inf  # REP 117 values are kept
                ranges[rng.random((n, k)) < 0.1] = np.nan
                values[column.name] = ranges
            else:
                values[column.name] = rng.normal(0.0, 10.0, (n, k)).astype(column.dtype)
        elif spec.name == "/scan":  # float32 on the wire
            values[column.name] = rng.uniform(0.0, 10.0, n).astype(np.float32).astype(np.float64)
        elif column.dtype == "uint8":
            values[column.name] = rng.integers(0, 256, n).astype(np.uint8)
        elif column.dtype == "int64":
            values[column.name] = rng.integers(-(2**62), 2**62, n)
        elif column.dtype == "object":
            values[column.name] = np.array(
                [json.dumps({"step": i, "note": 'ä, "q"\n'}) for i in range(n)], dtype=object
            )
        elif column.name == "distance_m":  # a range: reading drops negative ones
            values[column.name] = rng.uniform(0.0, 30.0, n)
        elif column.name == "yaw_rad":
            values[column.name] = rng.uniform(-np.pi + 1e-9, np.pi, n)
        else:
            values[column.name] = rng.normal(0.0, 10.0, n)
    return values


def sample_recording(rng: np.random.Generator, n: int = 40) -> Recording:
    """Every canonical topic with ``n`` rows (events: 3) at irregular, interleaved times."""
    builder = RecordingBuilder()
    for k, spec in enumerate(TOPICS.values()):
        m = 3 if spec.name == "/omnical/events" else n
        t_ns = T0_NS + np.sort(rng.integers(0, 5 * 10**9, m)) + k
        builder.add_many(spec.name, t_ns, **column_values(spec, m, rng))
    return builder.build()


def _stamp(store: Any, t_ns: int, frame_id: str, ros: RosVersion, seq: int) -> Any:
    types = store.types
    stamp = types["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
    if ros == 1:
        return types["std_msgs/msg/Header"](seq=seq, stamp=stamp, frame_id=frame_id)
    return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)


def oracle_message(spec: TopicSpec, table: Table, i: int, ros: RosVersion) -> Any:
    """Row ``i`` of ``table`` as a rosbags message object, built field by field."""
    store = typestore(ros)
    types = store.types
    msgtype = spec.ros2_type if ros == 2 else spec.ros1_type
    cls = types[msgtype]
    vec3 = types["geometry_msgs/msg/Vector3"]
    row = {name: table[name][i] for name in table.names}
    t_ns = int(table.t_ns[i])
    if spec.name == "/cmd_vel":
        return cls(
            linear=vec3(x=row["vx_mps"], y=row["vy_mps"], z=0.0),
            angular=vec3(x=0.0, y=0.0, z=row["wz_radps"]),
        )
    if spec.name in {"/odom", "/ground_truth"}:
        yaw = row["yaw_rad"]
        pose = types["geometry_msgs/msg/Pose"](
            position=types["geometry_msgs/msg/Point"](x=row["x_m"], y=row["y_m"], z=0.0),
            orientation=types["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2)
            ),
        )
        twist = types["geometry_msgs/msg/Twist"](
            linear=vec3(x=row["vx_mps"], y=row["vy_mps"], z=0.0),
            angular=vec3(x=0.0, y=0.0, z=row["wz_radps"]),
        )
        return cls(
            header=_stamp(store, t_ns, spec.frame_id, ros, i),
            child_frame_id=spec.child_frame_id,
            pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=types["geometry_msgs/msg/TwistWithCovariance"](
                twist=twist, covariance=np.zeros(36)
            ),
        )
    if spec.name == "/imu":
        orientation_cov = np.zeros(9)
        orientation_cov[0] = -1.0
        return cls(
            header=_stamp(store, t_ns, spec.frame_id, ros, i),
            orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=orientation_cov,
            angular_velocity=vec3(
                x=row["gyro_x_radps"], y=row["gyro_y_radps"], z=row["gyro_z_radps"]
            ),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vec3(x=row["acc_x_mps2"], y=row["acc_y_mps2"], z=row["acc_z_mps2"]),
            linear_acceleration_covariance=np.zeros(9),
        )
    if spec.name == "/hedge_pos_ang":
        return cls(
            address=int(row["address"]),
            timestamp_ms=int(row["timestamp_ms"]),
            x_m=row["x_m"],
            y_m=row["y_m"],
            z_m=row["z_m"],
            flags=int(row["flags"]),
            angle=row["angle_deg"],
        )
    if spec.name == "/beacon_raw_distance":
        return cls(
            address_hedge=int(row["address_hedge"]),
            address_beacon=int(row["address_beacon"]),
            distance_m=row["distance_m"],
        )
    if spec.name == "/beacons_pos_a":
        return cls(address=int(row["address"]), x_m=row["x_m"], y_m=row["y_m"], z_m=row["z_m"])
    if spec.name == "/scan":
        scalars = {
            k: float(row[f"{k}_{u}"])
            for k, u in (
                ("angle_min", "rad"),
                ("angle_max", "rad"),
                ("angle_increment", "rad"),
                ("time_increment", "s"),
                ("scan_time", "s"),
                ("range_min", "m"),
                ("range_max", "m"),
            )
        }
        return cls(
            header=_stamp(store, t_ns, spec.frame_id, ros, i),
            **scalars,
            ranges=np.asarray(row["ranges_m"], dtype=np.float32),
            intensities=np.asarray(row["intensities"], dtype=np.float32),
        )
    if spec.name == "/imu/mag":
        return cls(
            header=_stamp(store, t_ns, spec.frame_id, ros, i),
            magnetic_field=vec3(x=row["mag_x_t"], y=row["mag_y_t"], z=row["mag_z_t"]),
            magnetic_field_covariance=np.zeros(9),
        )
    if spec.name == "/dead_wheels":
        return cls(
            header=_stamp(store, t_ns, "", ros, i),
            name=[str(v) for v in row["name"]],
            position=np.asarray(row["position_rad"], dtype=np.float64),
            velocity=np.asarray(row["velocity_radps"], dtype=np.float64),
            effort=np.asarray(row["effort_nm"], dtype=np.float64),
        )
    if spec.name == "/hedge_quality":
        return cls(address=int(row["address"]), quality_percents=int(row["quality_percent"]))
    return cls(data=row["text"])


def oracle_bytes(spec: TopicSpec, table: Table, i: int, ros: RosVersion) -> bytes:
    """rosbags' own serialisation of row ``i``."""
    store = typestore(ros)
    msgtype = spec.ros2_type if ros == 2 else spec.ros1_type
    message = oracle_message(spec, table, i, ros)
    if ros == 2:
        return bytes(store.serialize_cdr(message, msgtype))
    return bytes(store.serialize_ros1(message, msgtype))


def assert_recordings_equal(a: Recording, b: Recording, *, yaw_atol: float = 1e-12) -> None:
    """Same topics, times and values (yaw up to rounding of the quaternion round trip)."""
    assert set(a.topics) == set(b.topics)
    for name in a.topics:
        ta, tb = a.topic(name), b.topic(name)
        np.testing.assert_array_equal(ta.t_ns, tb.t_ns, err_msg=name)
        assert ta.names == tb.names
        for column in ta.names:
            if column == "yaw_rad":
                np.testing.assert_allclose(ta[column], tb[column], rtol=0, atol=yaw_atol)
            elif ta[column].dtype == object:
                assert ta[column].tolist() == tb[column].tolist()
            else:
                assert ta[column].dtype == tb[column].dtype, (name, column)
                np.testing.assert_array_equal(ta[column], tb[column], err_msg=f"{name} {column}")


def exported_csv(recording: Recording, out_dir: Path) -> tuple[list[Path], Recording]:
    """``omnical export --format csv`` of ``recording`` written as a bag beside ``out_dir``: the
    files, and the recording as read back from that bag (what the files hold)."""
    from omnical.bags.bag import read_bag, write_bag
    from omnical.bags.export import export_bag_csv

    bag = write_bag(recording, out_dir.with_name(out_dir.name + "-bag"))
    return list(export_bag_csv(bag, out_dir).written), read_bag(bag)


def export_csv(recording: Recording, out_dir: Path) -> list[Path]:
    """The files of :func:`exported_csv`."""
    return exported_csv(recording, out_dir)[0]


def export_tum(recording: Recording, out_dir: Path) -> list[Path]:
    """``omnical export --format tum`` of ``recording``, written as a bag beside ``out_dir``."""
    from omnical.bags.bag import write_bag
    from omnical.bags.export import export_bag_tum

    bag = write_bag(recording, out_dir.with_name(out_dir.name + "-bag"))
    return list(export_bag_tum(bag, out_dir).written)

"""CSV and TUM exports parse back to the same numbers (pose topics read back as references); the
summary counts what is there."""

from __future__ import annotations

import csv
import importlib.util
import io
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from recording_samples import export_csv, export_tum, exported_csv, sample_recording

from omnical.bags.export import (
    export_poses_csv,
    export_poses_tum,
    tum_timestamp,
)
from omnical.bags.reference_topics import (
    bag_topics,
    pose_topics,
    read_pose_frames,
    read_pose_topic,
)
from omnical.evaluation.reference_input import read_reference, reference_from_poses
from omnical.recording.recording import Recording, RecordingBuilder, Table
from omnical.recording.summary import summarize
from omnical.recording.topics import GROUND_TRUTH, HEDGE_POS_ANG, ODOM

CMD_COLUMNS = ("vx_mps", "vy_mps", "wz_radps")


def test_csv_parses_back_to_the_same_values(tmp_path: Path) -> None:
    written = sample_recording(np.random.default_rng(31)).without(
        "/scan", "/dead_wheels", "/imu/mag"
    )  # array columns: tests/recording/test_recording_arrays.py
    files, recording = exported_csv(written, tmp_path / "csv")
    assert sorted(f.name for f in files) == sorted(
        [
            "cmd_vel.csv",
            "odom.csv",
            "ground_truth.csv",
            "imu.csv",
            "hedge_pos_ang.csv",
            "beacon_raw_distance.csv",
            "beacons_pos_a.csv",
            "hedge_quality.csv",
            "omnical_events.csv",
        ]
    )
    for path in files:
        topic = "/" + path.stem.replace("omnical_", "omnical/")
        table = recording.topic(topic)
        with path.open(newline="", encoding="utf-8") as stream:
            rows = list(csv.reader(stream))
        assert rows[0] == ["t_ns", *table.names]
        assert len(rows) == len(table) + 1
        np.testing.assert_array_equal([int(r[0]) for r in rows[1:]], table.t_ns)
        for k, name in enumerate(table.names, start=1):
            column = table[name]
            if column.dtype == object:
                assert [r[k] for r in rows[1:]] == list(column)
            else:
                parsed = np.array([r[k] for r in rows[1:]]).astype(column.dtype)
                np.testing.assert_array_equal(parsed, column)


def _read_tum(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text(encoding="utf-8").splitlines()
    stamps = [line.split()[0] for line in lines]
    values = np.array([[float(v) for v in line.split()[1:]] for line in lines])
    return stamps, values


def test_tum_trajectories(tmp_path: Path) -> None:
    recording = sample_recording(np.random.default_rng(32))
    hedge = recording.topic(HEDGE_POS_ANG)
    flags = np.where(np.arange(len(hedge)) % 3 == 0, 1, 2).astype(np.uint8)
    columns = {n: hedge[n] for n in hedge.names} | {
        "flags": flags,
        "address": np.full(len(hedge), 9, np.uint8),
    }
    recording = recording.with_table(HEDGE_POS_ANG, Table(hedge.t_ns, columns))
    files = export_tum(recording, tmp_path)
    assert [f.name for f in files] == ["odom.tum", "ground_truth.tum", "hedge_pos_ang.tum"]
    for topic, path in ((ODOM, files[0]), (GROUND_TRUTH, files[1])):
        table = recording.topic(topic)
        stamps, values = _read_tum(path)
        assert stamps == [f"{t // 10**9}.{t % 10**9:09d}" for t in table.t_ns.tolist()]
        np.testing.assert_array_equal(values[:, 0], table["x_m"])
        np.testing.assert_array_equal(values[:, 2], 0.0)
        yaw = 2.0 * np.arctan2(values[:, 5], values[:, 6])
        np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - table["yaw_rad"]))), 0.0, atol=1e-12)
    stamps, values = _read_tum(files[2])
    valid = hedge.take(flags & 1 == 0)
    assert len(stamps) == len(valid) == int(np.sum(flags & 1 == 0))
    np.testing.assert_array_equal(
        values[:, :3], np.column_stack([valid["x_m"], valid["y_m"], valid["z_m"]])
    )
    np.testing.assert_array_equal(values[:, 3:], np.tile([0.0, 0.0, 0.0, 1.0], (len(valid), 1)))


def test_tum_splits_hedgehogs_by_address(tmp_path: Path) -> None:
    builder = RecordingBuilder()
    for i, address in enumerate([3, 4, 3]):
        builder.add(
            HEDGE_POS_ANG,
            i,
            address=address,
            timestamp_ms=i,
            x_m=float(i),
            y_m=0.0,
            z_m=0.0,
            flags=2,
            angle_deg=0.0,
        )
    files = export_tum(builder.build(), tmp_path)
    assert [f.name for f in files] == ["hedge_pos_ang_3.tum", "hedge_pos_ang_4.tum"]
    assert _read_tum(files[0])[1][:, 0].tolist() == [0.0, 2.0]


def test_tum_timestamp_is_exact() -> None:
    assert tum_timestamp(1_700_000_000_000_000_001) == "1700000000.000000001"
    assert tum_timestamp(5) == "0.000000005"
    assert tum_timestamp(-1_500_000_000) == "-1.500000000"


def test_summary_counts_rates_and_travel() -> None:
    builder = RecordingBuilder()
    # a square of side 1 m driven at 10 Hz by odometry, 2 m straight by ground truth
    corners = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.0, 0.0)]
    for i, (x, y) in enumerate(corners):
        builder.add(
            ODOM,
            10**9 + i * 10**8,
            x_m=x,
            y_m=y,
            yaw_rad=0.1 * i,
            vx_mps=0.0,
            vy_mps=0.0,
            wz_radps=0.0,
        )
    for i in range(3):
        builder.add(
            GROUND_TRUTH,
            10**9 + i * 2 * 10**8,
            x_m=float(i),
            y_m=0.0,
            yaw_rad=0.0,
            vx_mps=0.0,
            vy_mps=0.0,
            wz_radps=0.0,
        )
    builder.add("/hedge_quality", 10**9 + 5 * 10**8, address=1, quality_percent=80)
    summary = summarize(builder.build())
    by_topic = {t.name: t for t in summary.topics}
    assert by_topic[ODOM].count == 5
    assert by_topic[ODOM].rate_hz == pytest.approx(10.0)
    assert by_topic["/hedge_quality"].rate_hz is None
    assert summary.duration_s == pytest.approx(0.5)
    assert summary.distance_odom_m == pytest.approx(4.0)
    assert summary.final_pose_odom == pytest.approx((0.0, 0.0, 0.4))
    assert summary.distance_ground_truth_m == pytest.approx(2.0)
    assert summary.final_pose_ground_truth == pytest.approx((2.0, 0.0, 0.0))


def test_summary_of_empty_recording() -> None:
    summary = summarize(Recording({}))
    assert summary.duration_s == 0.0
    assert summary.start_ns is None
    assert summary.distance_odom_m is None
    assert summary.final_pose_ground_truth is None
    assert math.isfinite(summary.duration_s)


def test_csv_of_many_rows_is_written_in_batches_and_whole(tmp_path: Path) -> None:
    n = 45_001  # more than two of the writer's batches, and not a multiple of one
    rng = np.random.default_rng(3)
    t_ns = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 5_000_000
    builder = RecordingBuilder()
    builder.add_many("/cmd_vel", t_ns, **{c: rng.normal(size=n) for c in CMD_COLUMNS})
    (path,) = export_csv(builder.build(), tmp_path)
    with path.open(encoding="utf-8") as stream:
        rows = list(csv.reader(stream))
    assert rows[0] == ["t_ns", *CMD_COLUMNS]
    assert len(rows) == n + 1
    assert [int(r[0]) for r in rows[1:]] == t_ns.tolist()
    table = builder.build().topic("/cmd_vel")
    for i, name in enumerate(CMD_COLUMNS, start=1):
        assert [float(r[i]) for r in rows[1:]] == table[name].tolist()


def _write_pose_bag() -> Any:
    path = Path(__file__).resolve().parents[1] / "estimation" / "mocap_bags.py"
    spec = importlib.util.spec_from_file_location("mocap_bags", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("mocap_bags", module)
    spec.loader.exec_module(module)
    return module.write_pose_bag


T0_NS = 1_700_000_000_123_456_789


def _poses(n: int = 30) -> tuple[np.ndarray, np.ndarray]:
    t_ns = T0_NS + np.arange(n, dtype=np.int64) * 10_000_001
    k = np.arange(n) * 0.05
    return t_ns, np.column_stack([np.cos(k), np.sin(k), 0.2 + k])


def test_tf_frames_and_pose_topics_are_listed_and_exported_per_child(tmp_path: Path) -> None:
    t_ns, poses = _poses()
    other = poses + np.array([1.0, 2.0, 0.1])
    write = _write_pose_bag()
    write(
        tmp_path / "tf",
        "/tf",
        "tf2_msgs/msg/TFMessage",
        t_ns,
        {"base_link": poses, "cart/x": other},
    )
    assert bag_topics(tmp_path / "tf") == {"/tf": "tf2_msgs/msg/TFMessage"}
    frames = read_pose_frames(tmp_path / "tf", "/tf")
    assert [f.child_frame_id for f in frames] == ["base_link", "cart/x"]
    files = export_poses_tum(frames, tmp_path / "out")
    assert [f.name for f in files] == ["tf_base_link.tum", "tf_cart_x.tum"]
    stamps, values = _read_tum(files[1])
    assert stamps == [tum_timestamp(t) for t in t_ns.tolist()]
    np.testing.assert_allclose(values[:, :2], other[:, :2], atol=1e-12)
    yaw = 2.0 * np.arctan2(values[:, 5], values[:, 6])
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - other[:, 2]))), 0.0, atol=1e-12)


def test_pose_topics_are_the_pose_types_omnical_does_not_read_itself() -> None:
    topics = {
        "/odom": "nav_msgs/msg/Odometry",
        "/ground_truth": "nav_msgs/msg/Odometry",
        "/odometry/filtered": "nav_msgs/msg/Odometry",
        "/mocap/pose": "geometry_msgs/msg/PoseStamped",
        "/amcl_pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
        "/vicon/robot": "geometry_msgs/msg/TransformStamped",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/imu": "sensor_msgs/msg/Imu",
        "/chatter": "std_msgs/msg/String",
    }
    assert pose_topics(topics) == [
        "/odometry/filtered",
        "/mocap/pose",
        "/amcl_pose",
        "/vicon/robot",
        "/tf",
    ]


@pytest.mark.parametrize("fmt", ["tum", "csv"])
def test_an_exported_pose_topic_reads_back_as_the_same_reference(tmp_path: Path, fmt: str) -> None:
    t_ns, poses = _poses()
    _write_pose_bag()(
        tmp_path / "b", "/mocap/pose", "geometry_msgs/msg/PoseStamped", t_ns, {"": poses}
    )
    pose = read_pose_topic(tmp_path / "b", "/mocap/pose")
    export = export_poses_tum if fmt == "tum" else export_poses_csv
    (path,) = export([pose], tmp_path / "out")
    assert path.name == f"mocap_pose.{fmt}"
    if fmt == "csv":
        assert path.read_text(encoding="utf-8").splitlines()[0] == "t_ns,x_m,y_m,yaw_rad"
    recording = Recording({"/mocap/pose": pose.table})
    got = read_reference(str(path), recording)
    want = reference_from_poses(pose.table, T0_NS)
    np.testing.assert_allclose(got.trajectory.t_s, want.t_s, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(got.trajectory.xy_m, want.xy_m)
    assert got.trajectory.yaw_rad is not None and want.yaw_rad is not None
    np.testing.assert_allclose(got.trajectory.yaw_rad, want.yaw_rad, atol=1e-12)


def test_csv_files_are_byte_for_byte_what_csv_writer_writes(tmp_path: Path) -> None:
    """Numbers formatted in bulk, column by column: the bytes of rows of Python objects through
    csv.writer (what the export wrote before), for every topic: arrays, text, integers."""
    files, recording = exported_csv(sample_recording(np.random.default_rng(33), n=57), tmp_path)
    for path in files:
        topic = next(t for t in recording.tables if path.stem == t.strip("/").replace("/", "_"))
        table = recording.topic(topic)
        header, columns = ["t_ns"], [table.t_ns]
        for name in table.names:
            values = table[name]
            if values.ndim == 1:
                header.append(name)
                columns.append(values)
            else:
                header.extend(f"{name}.{i}" for i in range(values.shape[1]))
                columns.extend(values[:, i] for i in range(values.shape[1]))
        expected = io.StringIO()
        writer = csv.writer(expected)
        writer.writerow(header)
        writer.writerows(zip(*(c.tolist() for c in columns), strict=True))
        assert path.read_bytes() == expected.getvalue().encode("utf-8"), topic

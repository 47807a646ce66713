"""External references: TUM/CSV files, pose topics of a bag (motion capture), and as fixes."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from omnical.bags.reference_topics import read_pose_topic
from omnical.calibration.campaign import ExternalReference, estimate_factors, reference_fixes
from omnical.errors import CalibrationError, ConfigError, RecordingError
from omnical.evaluation.reference_input import (
    TimeBase,
    load_reference,
    read_reference,
    reference_from_poses,
)
from omnical.ips.solve.fixes import FixStatus
from omnical.recording.recording import Recording, RecordingBuilder


def _mocap_bags() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "estimation" / "mocap_bags.py"
    spec = importlib.util.spec_from_file_location("mocap_bags", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("mocap_bags", module)
    spec.loader.exec_module(module)
    return module


write_pose_bag = _mocap_bags().write_pose_bag

T0_NS = 1_700_000_000_123_456_789


def _recording() -> Recording:
    b = RecordingBuilder()
    b.add_many(
        "/cmd_vel",
        np.array([T0_NS, T0_NS + 10**9]),
        vx_mps=[0.0, 0.1],
        vy_mps=[0, 0],
        wz_radps=[0, 0],
    )
    return b.build()


def _track(n: int = 50) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * 0.01
    poses = np.column_stack([np.cos(t), 2.0 * np.sin(t), 0.3 + 0.5 * t])
    return t, poses


def _tum_lines(stamps: np.ndarray, poses: np.ndarray) -> str:
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for s, (x, y, yaw) in zip(stamps, poses, strict=True):
        lines.append(
            f"{s:.9f} {x:.9f} {y:.9f} 0.1 0 0 {math.sin(yaw / 2):.12f} {math.cos(yaw / 2):.12f}"
        )
    return "\n".join(lines) + "\n"


def test_tum_with_absolute_times_is_taken_from_the_recording_start(tmp_path: Path) -> None:
    t, poses = _track()
    path = tmp_path / "traj.tum"
    path.write_text(_tum_lines(T0_NS / 1e9 + 2.0 + t, poses), encoding="utf-8")
    ref = load_reference(str(path), _recording())
    np.testing.assert_allclose(ref.t_s, 2.0 + t, atol=2e-6)  # float seconds of the epoch
    np.testing.assert_allclose(ref.xy_m, poses[:, :2], atol=1e-8)
    assert ref.yaw_rad is not None
    np.testing.assert_allclose(ref.yaw_rad, poses[:, 2], atol=1e-9)


def test_tum_with_relative_times_and_csv_with_yaw(tmp_path: Path) -> None:
    t, poses = _track()
    (tmp_path / "rel.txt").write_text(_tum_lines(1.5 + t, poses), encoding="utf-8")
    ref = load_reference(str(tmp_path / "rel.txt"), _recording())
    np.testing.assert_allclose(ref.t_s, 1.5 + t, atol=1e-9)
    rows = "\n".join(f"{a},{x},{y},{w}" for a, (x, y, w) in zip(t, poses, strict=True))
    (tmp_path / "ref.csv").write_text("t_s,x_m,y_m,yaw_rad\n" + rows + "\n", encoding="utf-8")
    csv = load_reference(str(tmp_path / "ref.csv"), _recording())
    assert csv.yaw_rad is not None
    np.testing.assert_allclose(csv.yaw_rad, poses[:, 2])


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("0.0 1 2 3 0 0 0\n1.0 1 2 3 0 0 0 1\n", "line 1: a TUM line"),
        ("1.0 1 2 3 0 0 0 1\n0.5 1 2 3 0 0 0 1\n", "timestamps must increase"),
        ("0.0 1 2 3 0 0 0 1\n", "at least two poses"),
        ("0.0 1 2 3 0 0 0 1\n1.0 nan 2 3 0 0 0 1\n", "finite"),
    ],
)
def test_bad_tum_files_are_refused(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.tum"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=match):
        load_reference(str(path), _recording())


TYPES = (
    "geometry_msgs/msg/PoseStamped",
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/TransformStamped",
    "tf2_msgs/msg/TFMessage",
)


@pytest.mark.parametrize("msgtype", TYPES)
def test_every_pose_type_reads_the_same_planar_poses(tmp_path: Path, msgtype: str) -> None:
    t, poses = _track()
    t_ns = T0_NS + np.round(t * 1e9).astype(np.int64)
    topic = "/tf" if msgtype.startswith("tf2") else "/mocap/robot"
    write_pose_bag(tmp_path / "b", topic, msgtype, t_ns, {"robot": poses})
    got = read_pose_topic(tmp_path / "b", topic)
    assert got.msgtype == msgtype and got.frame_id == "world"
    np.testing.assert_array_equal(got.table.t_ns, t_ns)
    np.testing.assert_allclose(got.table["x_m"], poses[:, 0], atol=1e-12)
    np.testing.assert_allclose(got.table["yaw_rad"], poses[:, 2], atol=1e-12)
    ref = reference_from_poses(got.table, T0_NS)
    np.testing.assert_allclose(ref.t_s, t, atol=1e-9)


def test_tf_needs_the_child_frame_when_it_carries_several(tmp_path: Path) -> None:
    t, poses = _track()
    other = poses + np.array([1.0, -1.0, 0.2])
    t_ns = T0_NS + np.round(t * 1e9).astype(np.int64)
    write_pose_bag(
        tmp_path / "tf", "/tf", "tf2_msgs/msg/TFMessage", t_ns, {"robot": poses, "cart": other}
    )
    with pytest.raises(ConfigError, match=r"2 child frames \(cart, robot\).*--reference-child"):
        read_pose_topic(tmp_path / "tf", "/tf")
    got = read_pose_topic(tmp_path / "tf", "tf", child_frame="/cart")
    assert got.child_frame_id == "cart"
    np.testing.assert_allclose(got.table["x_m"], other[:, 0], atol=1e-12)
    with pytest.raises(ConfigError, match="no transform to child frame 'robot2'"):
        read_pose_topic(tmp_path / "tf", "/tf", child_frame="robot2")


def test_a_topic_that_is_not_there_or_not_a_pose(tmp_path: Path) -> None:
    t, poses = _track()
    t_ns = T0_NS + np.round(t * 1e9).astype(np.int64)
    write_pose_bag(
        tmp_path / "b", "/mocap/pose", "geometry_msgs/msg/PoseStamped", t_ns, {"": poses}
    )
    with pytest.raises(RecordingError, match=r"no topic /robot/pose \(pose topics: /mocap/pose\)"):
        read_pose_topic(tmp_path / "b", "/robot/pose")
    with pytest.raises(ConfigError, match="has no child frame"):
        read_pose_topic(tmp_path / "b", "/mocap/pose", child_frame="robot")


def test_reference_fixes_are_thinned_ok_fixes() -> None:
    t_ns = T0_NS + np.arange(1000, dtype=np.int64) * 10_000_000  # 100 Hz, 10 s
    xy = np.column_stack([np.arange(1000) * 0.001, np.zeros(1000)])
    fixes = reference_fixes(ExternalReference(t_ns, xy, 0.003), rate_hz=20.0)
    assert len(fixes) == 200
    assert fixes.t_ns is not None
    assert np.all(np.diff(fixes.t_ns) == 50_000_000)
    assert np.all(fixes.status == FixStatus.OK)
    np.testing.assert_allclose(fixes.covariance_xy_m2[0], np.eye(2) * 0.003**2)
    with pytest.raises(CalibrationError, match="increasing"):
        reference_fixes(ExternalReference(t_ns[::-1], xy))


def test_external_references_need_the_joint_method() -> None:
    ref = ExternalReference(np.array([T0_NS, T0_NS + 1]), np.zeros((2, 2)))
    with pytest.raises(CalibrationError, match="joint method"):
        estimate_factors([_recording()], references=[ref])
    with pytest.raises(CalibrationError, match="2 references for 1 recordings"):
        estimate_factors([_recording()], method="joint", references=[ref, ref])


def _csv_text(header: str, times: list[str], poses: np.ndarray) -> str:
    rows = [f"{t},{x!r},{y!r},{w!r}" for t, (x, y, w) in zip(times, poses.tolist(), strict=True)]
    return header + "\n" + "\n".join(rows) + "\n"


def test_csv_with_absolute_seconds_is_bag_time_like_tum(tmp_path: Path) -> None:
    """Unix-epoch t_s were refused (±1e7 s); now they are bag times, like TUM's."""
    t, poses = _track()
    path = tmp_path / "epoch.csv"
    times = [f"{T0_NS / 1e9 + 2.0 + a:.9f}" for a in t]
    path.write_text(_csv_text("t_s,x_m,y_m,yaw_rad", times, poses), encoding="utf-8")
    loaded = read_reference(str(path), _recording())
    assert loaded.time_base is TimeBase.ABSOLUTE_S
    np.testing.assert_allclose(loaded.trajectory.t_s, 2.0 + t, atol=2e-6)
    assert loaded.times_note(T0_NS) == "reference times: absolute bag time (t_s ≥ 1e8 s)"
    tum = tmp_path / "epoch.tum"
    tum.write_text(_tum_lines(T0_NS / 1e9 + 2.0 + t, poses), encoding="utf-8")
    same = read_reference(str(tum), _recording())
    assert same.time_base is TimeBase.ABSOLUTE_S
    np.testing.assert_allclose(same.trajectory.t_s, loaded.trajectory.t_s, atol=2e-6)


def test_csv_with_t_ns_is_absolute_bag_time_exactly(tmp_path: Path) -> None:
    """omnical's own CSV export (t_ns, extra columns) is a reference as it is."""
    t, poses = _track()
    t_ns = T0_NS + 3 + np.round(t * 1e9).astype(np.int64)
    path = tmp_path / "odom.csv"
    text = "t_ns,x_m,y_m,yaw_rad,vx_mps\n" + "".join(
        f"{a},{x!r},{y!r},{w!r},0.0\n"
        for a, (x, y, w) in zip(t_ns.tolist(), poses.tolist(), strict=True)
    )
    path.write_text(text, encoding="utf-8")
    loaded = read_reference(str(path), _recording())
    assert loaded.time_base is TimeBase.ABSOLUTE_NS
    np.testing.assert_allclose(loaded.trajectory.t_s, (t_ns - T0_NS) / 1e9, rtol=0, atol=1e-12)
    assert loaded.trajectory.yaw_rad is not None
    np.testing.assert_array_equal(loaded.trajectory.xy_m, poses[:, :2])
    assert loaded.times_note(T0_NS) == "reference times: absolute bag time (t_ns)"


def test_small_seconds_stay_relative_and_the_note_says_so(tmp_path: Path) -> None:
    t, poses = _track()
    path = tmp_path / "rel.csv"
    path.write_text(
        _csv_text("t_s,x_m,y_m,yaw_rad", [repr(a) for a in (1.0 + t).tolist()], poses), "utf-8"
    )
    loaded = read_reference(str(path), _recording())
    assert loaded.time_base is TimeBase.RELATIVE_S
    np.testing.assert_allclose(loaded.trajectory.t_s, 1.0 + t)
    note = loaded.times_note(T0_NS)
    assert note == "reference times: relative to the bag start (t_s < 1e8 s)"
    # a bag whose own clock is small (simulated, converted): how to give bag times instead
    assert loaded.times_note(1_000_000_000).endswith(
        "; the bag's clock starts at 1.000 s: a t_ns column gives bag times"
    )


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("t_ns,x_m,y_m\n5,0,0\n5,1,1\n", "line 3: t_ns does not increase"),
        ("t_s,x_m,y_m\n\n1,0,0\n2,nan,1\n", r"line 4: x_m: not a finite number \(nan\)"),
        ("t_s,x_m,y_m\n1,0,0\ninf,1,1\n", r"line 3: t_s: not a finite number \(inf\)"),
        ("t_s,x_m,y_m\n1,0,0\n", "need at least two rows"),
        ("t_s,x_m,y_m\n\n\n1,0,0\n2,1e300,0\n", "line 5: t_s must lie within"),
        ("t_ns,x_m,y_m\n1,0,0\nx,1,1\n", "line 3: expected numbers in columns t_ns,x_m,y_m"),
        ("x_m,y_m\n0,0\n1,1\n", r"t_s \(or t_ns\),x_m,y_m \(missing t_s\)"),
        (f"t_s,x_m,y_m\n{T0_NS / 1e9 + 2e7},0,0\n{T0_NS / 1e9 + 2e7 + 1},1,1\n", "within ±1e"),
    ],
)
def test_bad_time_columns_are_refused(tmp_path: Path, text: str, match: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=match):
        load_reference(str(path), _recording())


def test_builtin_paths_start_with_the_motion() -> None:
    loaded = read_reference("circle", _recording())
    assert loaded.time_base is TimeBase.MOTION_START
    assert loaded.trajectory.t_s[0] == pytest.approx(1.0)
    assert loaded.times_note(T0_NS).endswith("first /cmd_vel motion (1.000 s after the bag start)")

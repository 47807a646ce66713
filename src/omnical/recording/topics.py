"""The canonical topics of an omnical recording, their message types and their columns.

Column names carry their units (SI unless named), rows are stamped in bag time ``t_ns``; scans
and JointStates are (N, k) blocks of one length per topic. Table: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
from types import MappingProxyType

import numpy as np

__all__ = [
    "BEACONS_POS_A",
    "BEACON_RAW_DISTANCE",
    "CMD_VEL",
    "DEAD_WHEELS",
    "EVALUATED",
    "EVENTS",
    "GROUND_TRUTH",
    "HEDGE_POS_ANG",
    "HEDGE_QUALITY",
    "IMU",
    "IMU_MAG",
    "IPS_FIX",
    "JOINT_STATES",
    "JOINT_STATE_COLUMNS",
    "MAP",
    "ODOM",
    "ODOM_CALIBRATED",
    "SCAN",
    "START",
    "TF",
    "TF_STATIC",
    "TOPICS",
    "ColumnSpec",
    "MessageKind",
    "TopicSpec",
    "joint_state_spec",
    "recognise_topic",
    "spec_of",
]

CMD_VEL = "/cmd_vel"
ODOM = "/odom"
GROUND_TRUTH = "/ground_truth"
IMU = "/imu"
HEDGE_POS_ANG = "/hedge_pos_ang"
BEACON_RAW_DISTANCE = "/beacon_raw_distance"
BEACONS_POS_A = "/beacons_pos_a"
HEDGE_QUALITY = "/hedge_quality"
EVENTS = "/omnical/events"
SCAN = "/scan"
IMU_MAG = "/imu/mag"
DEAD_WHEELS = "/dead_wheels"
JOINT_STATES = "/joint_states"  # a ROS 2 robot's wheel joints (sensor_msgs/JointState)
# Published live by omnical.ros2 (never recorded by omnical): TF, the corrected odometry, the
# hedgehog's fixes and a map.
TF = "/tf"
TF_STATIC = "/tf_static"
ODOM_CALIBRATED = "/odom_calibrated"
IPS_FIX = "/ips/fix"
MAP = "/map"
# Never in a bag: the empty one-row table evaluation.metrics.let_go leaves to keep a start.
START = "/omnical/start"

EVALUATED = (CMD_VEL, ODOM, IMU, GROUND_TRUTH, HEDGE_POS_ANG, BEACON_RAW_DISTANCE, BEACONS_POS_A)
"""What ``omnical evaluate`` reads of every run: the estimates, the reference and the commands."""


class MessageKind(Enum):
    """The message layouts omnical encodes and decodes."""

    TWIST = "geometry_msgs/msg/Twist"
    TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
    ODOMETRY = "nav_msgs/msg/Odometry"
    IMU = "sensor_msgs/msg/Imu"
    HEDGE_POS_ANG = "marvelmind/hedge_pos_ang"
    BEACON_DISTANCE = "marvelmind/beacon_distance"
    BEACON_POS_A = "marvelmind/beacon_pos_a"
    HEDGE_QUALITY = "marvelmind/hedge_quality"
    STRING = "std_msgs/msg/String"
    LASER_SCAN = "sensor_msgs/msg/LaserScan"
    MAGNETIC_FIELD = "sensor_msgs/msg/MagneticField"
    JOINT_STATE = "sensor_msgs/msg/JointState"


@dataclass(frozen=True)
class ColumnSpec:
    """One column of a topic table: its name (with unit), numpy dtype name, and whether each
    row holds an array (the column is then (N, k), k fixed per topic)."""

    name: str
    dtype: str
    array: bool = False


@dataclass(frozen=True)
class TopicSpec:
    """A canonical topic: name, message layout, columns and the types written to bags."""

    name: str
    kind: MessageKind
    columns: tuple[ColumnSpec, ...]
    ros2_type: str
    ros1_type: str
    frame_id: str = ""
    child_frame_id: str = ""

    @property
    def column_names(self) -> tuple[str, ...]:
        """Names of the columns, in order."""
        return tuple(c.name for c in self.columns)

    def dtype_of(self, column: str) -> np.dtype[np.generic]:
        """The numpy dtype of ``column``."""
        for c in self.columns:
            if c.name == column:
                return np.dtype(c.dtype)
        msg = f"topic {self.name}: no column {column!r} (columns: {', '.join(self.column_names)})"
        raise KeyError(msg)


def _floats(*names: str) -> tuple[ColumnSpec, ...]:
    return tuple(ColumnSpec(n, "float64") for n in names)


_POSE_TWIST = _floats("x_m", "y_m", "yaw_rad", "vx_mps", "vy_mps", "wz_radps")

JOINT_STATE_COLUMNS = (
    ColumnSpec("name", "object", array=True),
    ColumnSpec("position_rad", "float64", array=True),
    ColumnSpec("velocity_radps", "float64", array=True),
    ColumnSpec("effort_nm", "float64", array=True),
)
"""Columns of a JointState topic, each (N, joints) (velocity or effort may be (N, 0))."""


def joint_state_spec(name: str) -> TopicSpec:
    """The spec of a JointState topic called ``name``."""
    return TopicSpec(
        name,
        MessageKind.JOINT_STATE,
        JOINT_STATE_COLUMNS,
        "sensor_msgs/msg/JointState",
        "sensor_msgs/msg/JointState",
    )


_SPECS = (
    TopicSpec(
        CMD_VEL,
        MessageKind.TWIST,
        _floats("vx_mps", "vy_mps", "wz_radps"),
        "geometry_msgs/msg/Twist",
        "geometry_msgs/msg/Twist",
    ),
    TopicSpec(
        ODOM,
        MessageKind.ODOMETRY,
        _POSE_TWIST,
        "nav_msgs/msg/Odometry",
        "nav_msgs/msg/Odometry",
        frame_id="odom",
        child_frame_id="base_link",
    ),
    TopicSpec(
        GROUND_TRUTH,
        MessageKind.ODOMETRY,
        _POSE_TWIST,
        "nav_msgs/msg/Odometry",
        "nav_msgs/msg/Odometry",
        frame_id="map",
        child_frame_id="base_link",
    ),
    TopicSpec(
        IMU,
        MessageKind.IMU,
        _floats(
            "gyro_x_radps",
            "gyro_y_radps",
            "gyro_z_radps",
            "acc_x_mps2",
            "acc_y_mps2",
            "acc_z_mps2",
        ),
        "sensor_msgs/msg/Imu",
        "sensor_msgs/msg/Imu",
        frame_id="imu_link",
    ),
    TopicSpec(
        HEDGE_POS_ANG,
        MessageKind.HEDGE_POS_ANG,
        (
            ColumnSpec("address", "uint8"),
            ColumnSpec("timestamp_ms", "int64"),
            *_floats("x_m", "y_m", "z_m"),
            ColumnSpec("flags", "uint8"),
            ColumnSpec("angle_deg", "float64"),
        ),
        "marvelmind_ros2_msgs/msg/HedgePositionAngle",
        "marvelmind_nav/msg/hedge_pos_ang",
    ),
    TopicSpec(
        BEACON_RAW_DISTANCE,
        MessageKind.BEACON_DISTANCE,
        (
            ColumnSpec("address_hedge", "uint8"),
            ColumnSpec("address_beacon", "uint8"),
            ColumnSpec("distance_m", "float64"),
        ),
        "marvelmind_ros2_msgs/msg/BeaconDistance",
        "marvelmind_nav/msg/beacon_distance",
    ),
    TopicSpec(
        BEACONS_POS_A,
        MessageKind.BEACON_POS_A,
        (ColumnSpec("address", "uint8"), *_floats("x_m", "y_m", "z_m")),
        "marvelmind_ros2_msgs/msg/BeaconPositionAddressed",
        "marvelmind_nav/msg/beacon_pos_a",
    ),
    TopicSpec(
        HEDGE_QUALITY,
        MessageKind.HEDGE_QUALITY,
        (ColumnSpec("address", "uint8"), ColumnSpec("quality_percent", "uint8")),
        "marvelmind_ros2_msgs/msg/HedgeQuality",
        "marvelmind_nav/msg/hedge_quality",
    ),
    TopicSpec(
        EVENTS,
        MessageKind.STRING,
        (ColumnSpec("text", "object"),),
        "std_msgs/msg/String",
        "std_msgs/msg/String",
    ),
    TopicSpec(
        SCAN,
        MessageKind.LASER_SCAN,
        (
            *_floats(
                "angle_min_rad",
                "angle_max_rad",
                "angle_increment_rad",
                "time_increment_s",
                "scan_time_s",
                "range_min_m",
                "range_max_m",
            ),
            ColumnSpec("ranges_m", "float32", array=True),
            ColumnSpec("intensities", "float32", array=True),
        ),
        "sensor_msgs/msg/LaserScan",
        "sensor_msgs/msg/LaserScan",
        frame_id="laser",
    ),
    TopicSpec(
        IMU_MAG,
        MessageKind.MAGNETIC_FIELD,
        _floats("mag_x_t", "mag_y_t", "mag_z_t"),
        "sensor_msgs/msg/MagneticField",
        "sensor_msgs/msg/MagneticField",
        frame_id="imu_link",
    ),
    joint_state_spec(DEAD_WHEELS),
)

TOPICS: Mapping[str, TopicSpec] = MappingProxyType({s.name: s for s in _SPECS})
"""Every canonical topic by name."""

# Marvelmind topics are recognised by message type, whatever their name.
_BY_TYPE: Mapping[str, tuple[str, MessageKind]] = MappingProxyType(
    {
        t: (s.name, s.kind)
        for s in _SPECS
        if s.name in {HEDGE_POS_ANG, BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_QUALITY}
        for t in (s.ros2_type, s.ros1_type)
    }
)

# Standard topics are recognised by name (leading slash optional) and accepted types.
_BY_NAME: Mapping[str, Mapping[str, MessageKind]] = MappingProxyType(
    {
        CMD_VEL: {
            "geometry_msgs/msg/Twist": MessageKind.TWIST,
            "geometry_msgs/msg/TwistStamped": MessageKind.TWIST_STAMPED,
        },
        ODOM: {"nav_msgs/msg/Odometry": MessageKind.ODOMETRY},
        GROUND_TRUTH: {"nav_msgs/msg/Odometry": MessageKind.ODOMETRY},
        IMU: {"sensor_msgs/msg/Imu": MessageKind.IMU},
        EVENTS: {"std_msgs/msg/String": MessageKind.STRING},
        SCAN: {"sensor_msgs/msg/LaserScan": MessageKind.LASER_SCAN},
        IMU_MAG: {"sensor_msgs/msg/MagneticField": MessageKind.MAGNETIC_FIELD},
    }
)


def spec_of(topic: str, columns: tuple[str, ...] | None = None) -> TopicSpec | None:
    """The spec of ``topic``: a canonical one, or a JointState topic of any other name.

    A topic that is not canonical is a JointState topic when its ``columns`` are
    :data:`JOINT_STATE_COLUMNS`' (writing) or when ``columns`` is None and ``topic`` was
    recognised as one (reading); otherwise None.
    """
    if (spec := TOPICS.get(topic)) is not None:
        return spec
    names = tuple(c.name for c in JOINT_STATE_COLUMNS)
    if columns is None or tuple(columns) == names or set(columns) == set(names):
        return joint_state_spec(topic)
    return None


def recognise_topic(topic: str, msgtype: str) -> tuple[str, MessageKind] | None:
    """Map a bag connection to its canonical topic, or None if omnical does not use it.

    Marvelmind messages are recognised by type, whatever their topic; JointState messages by
    type, keeping their topic name (leading slash added); the standard topics by name (leading
    slash optional) and type.

    Args:
        topic: Topic name as stored in the bag.
        msgtype: Message type in rosbags' normalised form, e.g. ``nav_msgs/msg/Odometry``.

    Returns:
        ``(canonical topic, message kind)`` or None.
    """
    if (hit := _BY_TYPE.get(msgtype)) is not None:
        return hit
    name = topic if topic.startswith("/") else f"/{topic}"
    if msgtype == MessageKind.JOINT_STATE.value:
        return name, MessageKind.JOINT_STATE
    kinds = _BY_NAME.get(name)
    if kinds is not None and (kind := kinds.get(msgtype)) is not None:
        return name, kind
    return None

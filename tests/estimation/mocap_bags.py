"""Bags as a real Mecanum robot with motion capture records them, made from the twin.

Neither shared dataset (``../shared/datasets``: CUHK-SZ UWB, TU Chemnitz labyrinth) holds wheel
encoder ticks with motion capture (the TU Chemnitz robot is a differential drive with wheel
speeds, no ticks, no heading in its truth), so the recording comes from the twin, shaped like
the user's: a ROS 2 MCAP bag written with rosbags (not omnical's writer) holding

- ``/wheel_states`` ``sensor_msgs/JointState``: the four wheels' cumulative encoder ticks, 42
  counts per motor revolution through the 18.5:1 gearbox = 777 counts per wheel revolution,
  under the driver's own joint names and order, the right-hand encoders counting backwards;
  the wheel rotations are the twin's as its firmware measured them (recovered from its
  ``/odom`` through the inverse kinematics: ``/odom`` is their forward kinematics), floored to
  whole ticks at 50 Hz;
- ``/mocap/pose`` ``geometry_msgs/PoseStamped`` at 100 Hz: the twin's true pose of a marker
  body 4 cm ahead and 2 cm right of base_link, in the motion-capture room's own frame (shifted
  and turned from the beacon map), with 1 mm noise per axis;
- ``/imu`` ``sensor_msgs/Imu`` (the twin's);
- no ``/odom``, no ``/cmd_vel``, no Marvelmind topics, no ``/ground_truth``.

The twin's true factors (:data:`omnical.twin.params.ROSY_TRUTH` by default) are what a
calibration against ``/mocap/pose`` must find.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from omnical.experiment.script import CommandSource
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.jacobian import inverse_jacobian
from omnical.recording.recording import Recording
from omnical.robot.description import RobotDescription
from omnical.twin.params import TwinParams
from omnical.twin.session import simulate_run

COUNTS_PER_REV = 42 * 18.5
"""Encoder counts per wheel revolution: 42 per motor turn, 18.5:1 gearbox (777.0)."""
JOINTS = {  # the driver's joint name of each rosy-mecanum wheel, and its published order
    "front_left": "wheel_fl_joint",
    "front_right": "wheel_fr_joint",
    "rear_left": "wheel_rl_joint",
    "rear_right": "wheel_rr_joint",
}
REVERSED = ("front_right", "rear_right")
MARKER_OFFSET_M = (0.04, -0.02)
"""The motion-capture body's origin in base_link."""
MOCAP_FRAME = (2.0, -1.0, 0.5)
"""The beacon map's origin and heading in the motion-capture room's frame (x m, y m, yaw rad)."""
MOCAP_NOISE_M = 0.001
MOCAP_RATE_HZ = 100.0

F64 = NDArray[np.float64]


def robot_yaml(preset_text: str) -> str:
    """The rosy-mecanum description with the ``wheel_encoders`` section this bag needs."""
    joints = "\n".join(f"    {w}: {j}" for w, j in JOINTS.items())
    return (
        preset_text.rstrip("\n")
        + "\nwheel_encoders:\n"
        + f"  counts_per_rev: {COUNTS_PER_REV}\n"
        + f"  joints:\n{joints}\n"
        + f"  reversed: [{', '.join(REVERSED)}]\n"
    )


@dataclass(frozen=True)
class MocapRun:
    """A bag written as a user's robot would, and what the twin knows about it."""

    bag: Path
    truth: CorrectionFactors
    recording: Recording
    """The twin's own recording (with /odom, /ground_truth): for checks only."""


def _wheel_ticks(rec: Recording, robot: RobotDescription) -> tuple[NDArray[np.int64], F64]:
    """Bag times and (N, 4) signed ticks in JOINTS order, from the twin's /odom."""
    odom = rec.topic("/odom")
    p = np.column_stack([odom["x_m"], odom["y_m"], np.unwrap(odom["yaw_rad"])])
    dyaw = np.diff(p[:, 2])
    mid = p[:-1, 2] + 0.5 * dyaw
    d = np.diff(p[:, :2], axis=0)
    c, s = np.cos(mid), np.sin(mid)
    body = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], dyaw])
    angles = np.vstack(
        [np.zeros((1, 4)), np.cumsum(body @ inverse_jacobian(robot.wheels).T, axis=0)]
    )
    names = [w.name for w in robot.wheels]
    order = [names.index(w) for w in JOINTS]
    sign = np.array([-1.0 if w in REVERSED else 1.0 for w in JOINTS])
    ticks = np.floor(angles[:, order] * sign * COUNTS_PER_REV / (2.0 * math.pi))
    return odom.t_ns, ticks


def _mocap(rec: Recording, rng: np.random.Generator) -> tuple[NDArray[np.int64], F64]:
    gt = rec.topic("/ground_truth")
    x, y, yaw = gt["x_m"], gt["y_m"], gt["yaw_rad"]
    mx = x + np.cos(yaw) * MARKER_OFFSET_M[0] - np.sin(yaw) * MARKER_OFFSET_M[1]
    my = y + np.sin(yaw) * MARKER_OFFSET_M[0] + np.cos(yaw) * MARKER_OFFSET_M[1]
    ox, oy, oyaw = MOCAP_FRAME
    rx = ox + math.cos(oyaw) * mx - math.sin(oyaw) * my
    ry = oy + math.sin(oyaw) * mx + math.cos(oyaw) * my
    noise = rng.normal(0.0, MOCAP_NOISE_M, (rx.size, 2))
    return gt.t_ns, np.column_stack([rx + noise[:, 0], ry + noise[:, 1], yaw + oyaw])


def _stamp(store: Any, t_ns: int, frame: str) -> Any:
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    return Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id=frame)


def write_user_bag(path: Path, rec: Recording, seed: int) -> None:
    """Write ``rec`` (a twin run) as the user's bag at ``path`` (module docstring)."""
    from omnical.robot.loader import load_robot

    robot = load_robot("rosy-mecanum")
    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    t_w, ticks = _wheel_ticks(rec, robot)
    t_m, mocap = _mocap(rec, np.random.default_rng([seed, 0xC0DE]))
    imu = rec.topic("/imu")
    messages: list[tuple[int, str, Any]] = []
    joint_names = list(JOINTS.values())
    for t, row in zip(t_w.tolist(), ticks, strict=True):
        msg = T["sensor_msgs/msg/JointState"](
            header=_stamp(store, t, ""),
            name=joint_names,
            position=np.array(row, dtype=np.float64, order="C", copy=True),
            velocity=np.zeros(0),
            effort=np.zeros(0),
        )
        messages.append((t, "/wheel_states", msg))
    Pose, Point, Quat = (
        T["geometry_msgs/msg/Pose"],
        T["geometry_msgs/msg/Point"],
        T["geometry_msgs/msg/Quaternion"],
    )
    for t, (x, y, yaw) in zip(t_m.tolist(), mocap, strict=True):
        pose = Pose(
            position=Point(x=float(x), y=float(y), z=0.12),
            orientation=Quat(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
        )
        msg = T["geometry_msgs/msg/PoseStamped"](header=_stamp(store, t, "mocap_world"), pose=pose)
        messages.append((t, "/mocap/pose", msg))
    Vec = T["geometry_msgs/msg/Vector3"]
    cov = np.zeros(9)
    for i, t in enumerate(imu.t_ns.tolist()):
        msg = T["sensor_msgs/msg/Imu"](
            header=_stamp(store, t, "imu_link"),
            orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.array([-1.0, *cov[1:]]),
            angular_velocity=Vec(
                x=float(imu["gyro_x_radps"][i]),
                y=float(imu["gyro_y_radps"][i]),
                z=float(imu["gyro_z_radps"][i]),
            ),
            angular_velocity_covariance=cov,
            linear_acceleration=Vec(
                x=float(imu["acc_x_mps2"][i]),
                y=float(imu["acc_y_mps2"][i]),
                z=float(imu["acc_z_mps2"][i]),
            ),
            linear_acceleration_covariance=cov,
        )
        messages.append((t, "/imu", msg))
    messages.sort(key=lambda m: m[0])
    types = {
        "/wheel_states": "sensor_msgs/msg/JointState",
        "/mocap/pose": "geometry_msgs/msg/PoseStamped",
        "/imu": "sensor_msgs/msg/Imu",
    }
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {
            topic: writer.add_connection(topic, msgtype, typestore=store)
            for topic, msgtype in types.items()
        }
        for t, topic, msg in messages:
            writer.write(conns[topic], t, store.serialize_cdr(msg, types[topic]))


def twin_user_run(
    path: Path, script: CommandSource, robot: RobotDescription, params: TwinParams, seed: int
) -> MocapRun:
    """Run ``script`` on the twin (ground truth at the motion capture's rate) and write the bag."""
    rec = simulate_run(
        script, robot, replace(params, ground_truth_rate_hz=MOCAP_RATE_HZ), seed=seed
    )
    write_user_bag(path, rec, seed)
    return MocapRun(path, params.true_factors, rec)


def write_pose_bag(
    path: Path,
    topic: str,
    msgtype: str,
    t_ns: NDArray[np.int64],
    poses: dict[str, F64],
    *,
    frame: str = "world",
) -> None:
    """A ROS 2 bag with one pose topic: ``poses`` maps a child frame to (N, 3) x, y, yaw.

    ``tf2_msgs/msg/TFMessage`` puts every child's transform in each message; the other types
    (``PoseStamped``, ``Odometry``, ``TransformStamped``) take the single child given.
    """
    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    Quat, Vec = T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Vector3"]
    Point, Pose = T["geometry_msgs/msg/Point"], T["geometry_msgs/msg/Pose"]

    def quat(yaw: float) -> Any:
        return Quat(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))

    def transform(t: int, child: str, p: F64) -> Any:
        tr = T["geometry_msgs/msg/Transform"](
            translation=Vec(x=float(p[0]), y=float(p[1]), z=0.0), rotation=quat(float(p[2]))
        )
        return T["geometry_msgs/msg/TransformStamped"](
            header=_stamp(store, t, frame), child_frame_id=child, transform=tr
        )

    def pose(p: F64) -> Any:
        return Pose(
            position=Point(x=float(p[0]), y=float(p[1]), z=0.0), orientation=quat(float(p[2]))
        )

    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(topic, msgtype, typestore=store)
        for i, t in enumerate(t_ns.tolist()):
            if msgtype == "tf2_msgs/msg/TFMessage":
                msg = T[msgtype](transforms=[transform(t, c, p[i]) for c, p in poses.items()])
            else:
                ((child, p),) = poses.items()
                if msgtype == "geometry_msgs/msg/TransformStamped":
                    msg = transform(t, child, p[i])
                elif msgtype == "nav_msgs/msg/Odometry":
                    cov = np.zeros(36)
                    msg = T[msgtype](
                        header=_stamp(store, t, frame),
                        child_frame_id=child,
                        pose=T["geometry_msgs/msg/PoseWithCovariance"](
                            pose=pose(p[i]), covariance=cov
                        ),
                        twist=T["geometry_msgs/msg/TwistWithCovariance"](
                            twist=T["geometry_msgs/msg/Twist"](
                                linear=Vec(x=0.0, y=0.0, z=0.0), angular=Vec(x=0.0, y=0.0, z=0.0)
                            ),
                            covariance=cov,
                        ),
                    )
                else:
                    msg = T[msgtype](header=_stamp(store, t, frame), pose=pose(p[i]))
            writer.write(conn, t, store.serialize_cdr(msg, msgtype))

"""``omnical map``: SLAM on a recording's /scan and /odom → a map_server map, the trajectory and
a figure (seed 001 Fig. 12), written beside each other and put in place together at the end."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, Robot
from omnical.cli.output import say

if TYPE_CHECKING:
    from omnical.recording.recording import Recording

__all__ = ["map_command"]


def map_command(
    run: Annotated[
        Path,
        typer.Argument(metavar="BAG", help="Recording with /scan and /odom (ROS 2 or ROS 1 bag)."),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            "-o",
            help="Map to write: MAP.yaml (+ MAP.pgm, the trajectory MAP.tum, the figure MAP.png).",
        ),
    ],
    initial_pose: Annotated[
        str | None,
        typer.Option(
            "--initial-pose",
            metavar="X,Y,YAW",
            help="Pose X,Y,YAW (m, m, rad; or YAW in degrees as 90deg) of the robot at the first "
            "scan: the map is in that frame (on the twin: the world's). Default: the frame of "
            "the first pose.",
        ),
    ] = None,
    robot: Robot = "rosy-mecanum",
    overwrite: Overwrite = False,
) -> None:
    """Build an occupancy map from a recording's LiDAR scans and wheel odometry (SLAM)."""
    with handled_errors():
        import math

        from omnical.bags.bag import read_bag
        from omnical.cli.output import tell
        from omnical.cli.plan import parse_xy
        from omnical.cli.robot_target import load_said_robot
        from omnical.errors import ConfigError
        from omnical.navigation.map_io import MAX_ORIGIN_M
        from omnical.recording.topics import GROUND_TRUTH, ODOM, SCAN
        from omnical.reports.navigation import map_output_paths, write_map_outputs
        from omnical.reports.outputs import stage_files
        from omnical.services.navigation import map_from_recording

        if out.suffix not in {".yaml", ".yml"}:
            msg = f"--out {out}: give the map's YAML file (MAP.yaml)"
            raise ConfigError(msg)
        final = list(map_output_paths(out).values())
        outputs = stage_files(final, overwrite=overwrite, notify=tell)
        pose = None
        if initial_pose is not None:
            x, y, yaw = parse_xy(initial_pose, "--initial-pose", 3)
            if max(abs(x), abs(y)) > MAX_ORIGIN_M:  # the map's origin would be refused by plan
                msg = (
                    f"--initial-pose {initial_pose}: x, y must lie within "
                    f"±{MAX_ORIGIN_M:.0f} m (a map's origin must), got {x:g}, {y:g}"
                )
                raise ConfigError(msg)
            pose = (x, y, yaw)
        description = load_said_robot(robot)
        mount = description.lidar_mount
        recording = read_bag(run, [SCAN, ODOM, GROUND_TRUTH])
        missing = [t for t in (SCAN, ODOM) if not recording.has(t)]
        if missing:
            from omnical.bags.reference_topics import bag_topics
            from omnical.errors import RecordingError

            have = ", ".join(f"{t} ({kind})" for t, kind in sorted(bag_topics(run).items()))
            msg = (
                f"{run}: no {' and no '.join(missing)} to map from (SLAM needs a LiDAR's "
                f"sensor_msgs/LaserScan on /scan and nav_msgs/Odometry on /odom); the bag has: "
                f"{have or 'no topics'}"
            )
            raise RecordingError(msg)
        for note in recording.notes:
            say(f"warning: {note}")
        if recording.has(GROUND_TRUTH) and len(recording.topic(GROUND_TRUTH)):
            _check_start(pose, recording)
        recorded = map_from_recording(
            recording, initial_pose=pose, mount_pose=(mount.x_m, mount.y_m, mount.yaw_rad)
        )
        with outputs.staged(tell) as staged:
            write_map_outputs(recorded, staged[0], source=run.name)
        slam = recorded.slam
        duration = float(slam.t_s[-1] - slam.t_s[0])
        say(
            f"{len(slam.poses)} scans, {len(slam.keyframes)} keyframes, "
            f"{len(slam.loop_closures)} loop closures, {int(slam.degenerate.sum())} degenerate "
            f"matches; SLAM {recorded.slam_time_s:.1f} s for {duration:.0f} s of robot time"
        )
        if math.isfinite(recorded.trajectory_rmse_m):
            say(
                f"against /ground_truth: RMSE {recorded.trajectory_rmse_m * 100:.1f} cm, yaw "
                f"{math.degrees(recorded.yaw_rmse_rad):.2f}° (raw odometry "
                f"{recorded.odometry_rmse_m * 100:.1f} cm)"
            )
        say("wrote " + ", ".join(str(p) for p in final))


START_TOLERANCE_M = 0.2
START_TOLERANCE_RAD = 0.1


def _check_start(pose: tuple[float, float, float] | None, recording: Recording) -> None:
    """The start the map is built from against the bag's /ground_truth at the first scan: a
    warning naming the start that puts the map in the world's frame when they differ."""
    import math

    import numpy as np

    from omnical.recording.topics import GROUND_TRUTH, SCAN

    gt = recording.topic(GROUND_TRUTH)
    t0 = int(recording.topic(SCAN).t_ns[0])
    i = int(np.clip(np.searchsorted(gt.t_ns, t0), 0, len(gt) - 1))
    x, y, yaw = float(gt["x_m"][i]), float(gt["y_m"][i]), float(gt["yaw_rad"][i])
    given = pose if pose is not None else (0.0, 0.0, 0.0)
    off_m = math.hypot(given[0] - x, given[1] - y)
    off_rad = abs(math.remainder(given[2] - yaw, 2.0 * math.pi))
    if off_m <= START_TOLERANCE_M and off_rad <= START_TOLERANCE_RAD:
        return
    what = (
        f"--initial-pose {given[0]:g},{given[1]:g},{given[2]:g}"
        if pose is not None
        else "without --initial-pose the map is in the frame of the first pose, which"
    )
    say(
        f"warning: {what} is {off_m:.2f} m and {math.degrees(off_rad):.1f}° from where the "
        f"bag's /ground_truth starts ({x:.2f}, {y:.2f}, {yaw:.3f} rad): the map is not in the "
        f"world's frame; --initial-pose {x:.3g},{y:.3g},{yaw:.3g} puts it there"
    )

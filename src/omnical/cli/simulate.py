"""``omnical simulate``: run a motion script on the digital twin and record it as a ROS bag.

The output is checked before the run; Ctrl-C or SIGTERM stops the robot and keeps the run as
``RUN.partial`` (exit 130 / 143), never over an earlier complete run.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Annotated, Any

import typer

from omnical.cli.errors import EXIT_NO_RESULT, Terminated, handled_errors
from omnical.cli.options import Beacons, Overwrite, Robot, Seed
from omnical.cli.output import say

if TYPE_CHECKING:
    from omnical.recording.recording import Recording
    from omnical.twin.world import World

__all__ = ["simulate"]

_NS_PER_S = 1_000_000_000


def simulate(
    script: Annotated[
        str,
        typer.Argument(
            help="Motion script YAML, or a built-in name (tour, straight-10m, lab-tour)."
        ),
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out", "-o", help="Recording to write: RUN.mcap (ROS 2) or RUN.bag (ROS 1)."
        ),
    ],
    robot: Robot = "rosy-mecanum",
    twin: Annotated[str, typer.Option(help="Twin YAML, or 'default' / 'ideal'.")] = "default",
    seed: Seed = 0,
    beacons: Beacons = None,
    overwrite: Overwrite = False,
    uncompressed: Annotated[
        bool,
        typer.Option(
            "--uncompressed",
            help="Write the bag without chunk compression (default: zstd MCAP chunks, "
            "lz4 for ROS 1 .bag).",
        ),
    ] = False,
    world: Annotated[
        Path | None,
        typer.Option(
            "--world",
            help="Floor plan (map_server YAML, or a shipped world: lab-8x6, warehouse-20x20): "
            "the recording gains the LiDAR's /scan (for omnical map); a collision of the "
            "footprint with a wall stops the run there (exit status 3).",
        ),
    ] = None,
) -> None:
    """Run a motion script on the digital twin and record it as a ROS bag."""
    with handled_errors():
        from omnical.bags.bag import check_bag_output, partial_location, write_bag
        from omnical.bags.sink import BagCompression
        from omnical.cli.progress import robot_time_progress
        from omnical.cli.robot_target import load_said_robot
        from omnical.experiment.script import load_script
        from omnical.ips.beacons import load_beacon_map
        from omnical.twin.params import load_twin
        from omnical.twin.session import simulate_run

        # the output first: an existing file that is not omnical's bag, or a read-only place,
        # is refused before a second of simulation
        target = check_bag_output(out, overwrite=overwrite)
        earlier = target.exists()
        compression: BagCompression | None = None if uncompressed else "auto"
        bmap = load_beacon_map(beacons) if beacons is not None else None
        description = load_said_robot(robot)
        params = load_twin(twin, description, bmap)
        compiled = load_script(script, description.limits)
        floor_plan = None
        if world is not None:
            from omnical.cli.options import twin_start_fix
            from omnical.services.navigation import robot_world
            from omnical.twin.world import check_start

            floor_plan = robot_world(world, description)
            check_start(floor_plan, params.start_pose_map, "the twin's start", twin_start_fix(twin))
        with _noted_signals(raise_first=True) as signals:
            with robot_time_progress(f"simulating {compiled.name}") as progress:

                def tick(done_s: float, total_s: float) -> None:
                    progress(done_s, total_s)
                    if done_s >= total_s:  # the script ran to its end: a signal now only stops
                        signals.raise_first = False  # omnical once the run is kept

                recording = simulate_run(
                    compiled,
                    description,
                    params,
                    seed=seed,
                    beacons=bmap,
                    on_tick=tick,
                    world=floor_plan,
                    keep_interrupted=True,
                )
            signals.raise_first = False  # from here every signal is noted: the run is kept first
            # a signal came: the runner caught it while the script ran and stopped early, or it
            # was noted after the script's end
            interrupted = signals.first is not None
            collision = (
                _stop_at_collision(recording, floor_plan) if floor_plan is not None else None
            )
            if collision is not None:
                recording, collision_line = collision
            if interrupted:
                kept = write_bag(recording, partial_location(target), compression=compression)
            else:  # a signal while it is written: the finished bag is kept as RUN.partial
                kept = write_bag(
                    recording,
                    out,
                    overwrite=overwrite,
                    compression=compression,
                    divert=lambda: signals.first is not None,
                )
        if kept != target:
            done_s = _script_time_s(recording)
            typer.echo(
                f"omnical: kept the {'partial' if signals.raised else 'whole'} run in {kept} "
                f"({done_s:.1f} s of the script's {compiled.duration_s:.1f} s, "
                f"{recording.message_count} messages)"
                + (f"; the earlier {target} was not touched" if earlier else ""),
                err=True,
            )
        else:
            say(f"wrote {kept} ({recording.duration_s:.1f} s, {recording.message_count} messages)")
        signals.reraise()  # a signal came: stop as it asks, now that the run is kept
        if collision is not None:
            typer.echo(f"omnical: {collision_line}", err=True)
            raise typer.Exit(EXIT_NO_RESULT)


@dataclass
class _Signals:
    """The stop signals received while a block ran (the first one decides the exit status)."""

    received: list[int]
    raise_first: bool
    announced: bool = False
    raised: bool = False  # the first one raised: the run was cut there

    @property
    def first(self) -> int | None:
        return self.received[0] if self.received else None

    def reraise(self) -> None:
        """Stop as the first signal asks (exit 143 for SIGTERM, else 130)."""
        if self.first == signal.SIGTERM:
            raise Terminated
        if self.first is not None:
            raise KeyboardInterrupt


@contextmanager
def _noted_signals(*, raise_first: bool) -> Iterator[_Signals]:
    """Note SIGINT / SIGTERM while the block runs.

    ``raise_first``: the first signal raises ``KeyboardInterrupt`` (``Terminated`` for
    SIGTERM) as usual, later ones are only noted (the run is already stopping and its
    recording is being assembled); otherwise — or once ``raise_first`` is set False, when the
    script has run to its end — every signal is only noted (a bag being written is finished
    first). Outside the main thread signals cannot be caught: nothing changes.
    """
    noted = _Signals([], raise_first)
    if threading.current_thread() is not threading.main_thread():
        yield noted
        return

    def handler(signum: int, frame: FrameType | None) -> None:
        noted.received.append(signum)
        if noted.raise_first and len(noted.received) == 1:
            noted.raised = True
            raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt
        if not noted.announced:
            noted.announced = True
            typer.echo("omnical: stopping as soon as the recording is written", err=True)

    previous: dict[signal.Signals, Any] = {}
    for stop in (signal.SIGINT, signal.SIGTERM):
        previous[stop] = signal.signal(stop, handler)
    try:
        yield noted
    finally:
        for stop, old in previous.items():
            signal.signal(stop, old)


def _stop_at_collision(recording: Recording, world: World) -> tuple[Recording, str] | None:
    """The run up to the first ground-truth pose whose footprint touches a wall of ``world``,
    and the line that says so; None when the footprint stays free all along."""
    import numpy as np

    from omnical.recording.recording import Recording as _Recording
    from omnical.recording.topics import GROUND_TRUTH

    if not recording.has(GROUND_TRUTH):
        return None
    gt = recording.topic(GROUND_TRUTH)
    poses = np.column_stack([gt["x_m"], gt["y_m"], gt["yaw_rad"]])
    first = world.first_collision(poses)
    if first is None:
        return None
    t_stop_ns = int(gt.t_ns[first])
    kept = {
        name: table.between(recording.start_ns, t_stop_ns + 1)
        for name, table in recording.tables.items()
    }
    line = (
        f"{world.collision_message(poses[first])} after "
        f"{(t_stop_ns - recording.start_ns) / _NS_PER_S:.1f} s of the run: the run stops there "
        "(recorded up to it); the script does not fit this world"
    )
    return _Recording(kept, recording.skipped_topics, recording.notes), line


def _script_time_s(recording: Recording) -> float:
    """Script time covered by the recorded commands (first to last ``/cmd_vel``), s."""
    from omnical.recording.topics import CMD_VEL

    table = recording.tables.get(CMD_VEL)
    if table is None or len(table) < 2:
        return 0.0
    return float(int(table.t_ns[-1]) - int(table.t_ns[0])) / _NS_PER_S

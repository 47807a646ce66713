"""``omnical simulate``: run a motion script on the digital twin and record it as a ROS bag."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.options import Beacons, Robot, Seed
from omnical.cli.output import say

__all__ = ["simulate"]


def simulate(
    script: Annotated[
        str, typer.Argument(help="Motion script YAML, or a built-in name (tour, straight-10m).")
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
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace an existing recording.")
    ] = False,
    uncompressed: Annotated[
        bool,
        typer.Option(
            "--uncompressed",
            help="Write the bag without chunk compression (default: zstd MCAP chunks, "
            "lz4 for ROS 1 .bag).",
        ),
    ] = False,
) -> None:
    """Run a motion script on the digital twin and record it as a ROS bag."""
    with handled_errors():
        _simulate_and_write(script, out, robot, twin, seed, beacons, overwrite, uncompressed)


def _simulate_and_write(
    script: str,
    out: Path,
    robot: str,
    twin: str,
    seed: int,
    beacons: Path | None,
    overwrite: bool,
    uncompressed: bool = False,
) -> None:
    from omnical.cli.progress import robot_time_progress
    from omnical.errors import ConfigError
    from omnical.experiment.script import load_script
    from omnical.ips.beacons import load_beacon_map
    from omnical.recording.bag import bag_location, write_bag
    from omnical.robot.loader import load_robot
    from omnical.twin.params import load_twin
    from omnical.twin.session import simulate_run

    if not overwrite and bag_location(out).exists():
        msg = f"{bag_location(out)}: already exists; choose another --out or pass --overwrite"
        raise ConfigError(msg)
    bmap = load_beacon_map(beacons) if beacons is not None else None
    description = load_robot(robot)
    params = load_twin(twin, description)
    compiled = load_script(script, description.limits)
    with robot_time_progress(f"simulating {compiled.name}") as tick:
        recording = simulate_run(
            compiled, description, params, seed=seed, beacons=bmap, on_tick=tick
        )
    written = write_bag(
        recording, out, overwrite=overwrite, compression=None if uncompressed else "auto"
    )
    messages = sum(len(t) for t in recording.tables.values())
    say(f"wrote {written} ({recording.duration_s:.1f} s, {messages} messages)")

"""``omnical navigate``: plan and drive legs between points on the twin in a floor plan."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.output import say

__all__ = ["navigate"]


def navigate(
    world: Annotated[Path, typer.Option(help="Floor plan the twin drives in (map_server YAML).")],
    map_yaml: Annotated[Path, typer.Option("--map", help="Map to plan and localise on.")],
    start: Annotated[str, typer.Option(help="Start pose X,Y,YAW (m, m, rad), world frame.")],
    goal: Annotated[list[str], typer.Option(help="Goal X,Y; repeat for several legs.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Bag of the run (odometry, truth).")],
    robot: Annotated[str, typer.Option(help="Robot preset or file.")] = "rosy-mecanum",
    seed: Annotated[int, typer.Option(help="Twin seed.")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing bag.")] = False,
) -> None:
    """Navigate between points: PRM legs, seed 001's way-point controller, scan-to-map localisation."""
    with handled_errors():
        _navigate(world, map_yaml, start, goal, out, robot, seed, overwrite)


def _navigate(
    world_yaml: Path,
    map_yaml: Path,
    start: str,
    goals: list[str],
    out: Path,
    robot: str,
    seed: int,
    overwrite: bool,
) -> None:
    from dataclasses import replace

    import numpy as np

    from omnical.cli.plan import parse_xy
    from omnical.navigation.map_io import load_map
    from omnical.recording.bag import check_bag_output, write_bag
    from omnical.recording.recording import RecordingBuilder
    from omnical.robot.loader import load_robot
    from omnical.services.navigation import navigate as run_navigation
    from omnical.twin.params import default_twin
    from omnical.twin.session import EPOCH_NS, twin_recording
    from omnical.twin.world import load_world

    check_bag_output(out, overwrite=overwrite)
    pose = parse_xy(start, "--start", 3)
    targets = [parse_xy(g, "--goal") for g in goals]
    description = load_robot(robot)
    params = replace(default_twin(description), start_pose_map=(pose[0], pose[1], pose[2]))
    w = load_world(world_yaml)
    run = run_navigation(
        w, load_map(map_yaml), description, params, [(t[0], t[1]) for t in targets], seed=seed
    )
    builder = RecordingBuilder()
    cmds = [leg.control.cmd_vel for leg in run.legs if leg.control is not None]
    if cmds:
        cmd = np.vstack(cmds)
        stamps = EPOCH_NS + np.round(cmd[:, 0] * 1e9).astype(np.int64)
        builder.add_many("/cmd_vel", stamps, vx_mps=cmd[:, 1], vy_mps=cmd[:, 2], wz_radps=cmd[:, 3])
    twin_recording(builder, run.twin_log, description, params, seed=seed)
    written = write_bag(builder.build(), out, overwrite=overwrite)
    for k, leg in enumerate(run.legs, 1):
        state = leg.control.reason if leg.control is not None else "-"
        say(
            f"leg {k} to {leg.goal_m}: plan {leg.plan.status} ({leg.plan.method or leg.plan.reason}), "
            f"control {state}, goal error {leg.goal_error_m * 100:.1f} cm"
        )
    if run.collision:
        say(run.collision)
    say(f"min clearance {run.min_clearance_m * 100:.1f} cm; wrote {written}")
    if not run.reached:
        raise typer.Exit(1)

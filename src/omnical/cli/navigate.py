"""``omnical navigate``: plan and drive legs between points on the twin in a floor plan."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import EXIT_NO_RESULT, handled_errors
from omnical.cli.output import say

__all__ = ["navigate"]


def navigate(
    world: Annotated[
        Path,
        typer.Option(
            help="Floor plan the twin drives in: map_server YAML, or a shipped world "
            "(lab-8x6, warehouse-20x20)."
        ),
    ],
    map_yaml: Annotated[Path, typer.Option("--map", help="Map to plan and localise on.")],
    start: Annotated[str, typer.Option(help="Start pose X,Y,YAW (m, m, rad), world frame.")],
    goal: Annotated[list[str], typer.Option(help="Goal X,Y; repeat for several legs.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Bag of the run (odometry, truth).")],
    robot: Annotated[str, typer.Option(help="Robot preset or file.")] = "rosy-mecanum",
    seed: Annotated[int, typer.Option(help="Twin seed.")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing bag.")] = False,
    controller: Annotated[
        list[str] | None,
        typer.Option(
            help="Controller of the legs: waypoint (seed 001: turn, then drive) or tracking "
            "(holonomic tracker); once for every leg, or once per --goal.",
        ),
    ] = None,
) -> None:
    """Navigate between points: PRM legs, seed 001's way-point controller or the holonomic
    tracker, scan-to-map localisation. Writes the bag (with /scan) and NAV.png beside it."""
    with handled_errors():
        _navigate(world, map_yaml, start, goal, out, robot, seed, overwrite, controller or [])


def _navigate(
    world_yaml: Path,
    map_yaml: Path,
    start: str,
    goals: list[str],
    out: Path,
    robot: str,
    seed: int,
    overwrite: bool,
    controllers: list[str],
) -> None:
    from dataclasses import replace

    import numpy as np

    from omnical.cli.plan import parse_xy
    from omnical.errors import ConfigError
    from omnical.navigation.map_io import load_map
    from omnical.recording.bag import check_bag_output, write_bag
    from omnical.recording.recording import RecordingBuilder
    from omnical.reports.navigation import write_navigation_figure
    from omnical.reports.outputs import claim_files
    from omnical.robot.loader import load_robot
    from omnical.services.navigation import navigate as run_navigation
    from omnical.services.navigation import robot_world
    from omnical.twin.params import default_twin
    from omnical.twin.session import EPOCH_NS, twin_recording

    target = check_bag_output(out, overwrite=overwrite)
    figure = target.with_name(target.name.removesuffix(".bag") + ".png")
    claim_files([figure], overwrite=overwrite)
    pose = parse_xy(start, "--start", 3)
    targets = [parse_xy(g, "--goal") for g in goals]
    for c in controllers:
        if c not in ("waypoint", "tracking"):
            msg = f"--controller: {c!r} is not one of waypoint, tracking"
            raise ConfigError(msg)
    if len(controllers) not in (0, 1, len(targets)):
        msg = f"--controller: give it once or once per --goal ({len(targets)}), not {len(controllers)} times"
        raise ConfigError(msg)
    choices = controllers * len(targets) if len(controllers) == 1 else controllers
    description = load_robot(robot)
    params = replace(default_twin(description), start_pose_map=(pose[0], pose[1], pose[2]))
    w = robot_world(world_yaml, description)
    map_grid = load_map(map_yaml)
    run = run_navigation(
        w,
        map_grid,
        description,
        params,
        [(t[0], t[1]) for t in targets],
        seed=seed,
        controller=choices or "waypoint",  # type: ignore[arg-type]
    )
    if not any(leg.control is not None for leg in run.legs):  # nothing moved: nothing to keep
        for k, leg in enumerate(run.legs, 1):
            say(f"leg {k} to {leg.goal_m}: plan {leg.plan.status}: {leg.plan.reason}")
        say("the robot did not move; no bag written")
        raise typer.Exit(EXIT_NO_RESULT)
    builder = RecordingBuilder()
    cmds = [leg.control.cmd_vel for leg in run.legs if leg.control is not None]
    if cmds:
        cmd = np.vstack(cmds)
        stamps = EPOCH_NS + np.round(cmd[:, 0] * 1e9).astype(np.int64)
        builder.add_many("/cmd_vel", stamps, vx_mps=cmd[:, 1], vy_mps=cmd[:, 2], wz_radps=cmd[:, 3])
    twin_recording(builder, run.twin_log, description, params, seed=seed, world=w)
    written = write_bag(builder.build(), out, overwrite=overwrite)
    write_navigation_figure(run, map_grid, figure, f"navigate on {map_yaml.name}")
    for k, leg in enumerate(run.legs, 1):
        state = leg.control.reason if leg.control is not None else "-"
        say(
            f"leg {k} to {leg.goal_m} ({leg.controller}): plan {leg.plan.status} "
            f"({leg.plan.method or leg.plan.reason}), control {state}, "
            f"goal error {leg.goal_error_m * 100:.1f} cm"
        )
    if run.collision:
        say(run.collision)
    say(f"min clearance {run.min_clearance_m * 100:.1f} cm; wrote {written} and {figure}")
    if not run.reached:
        raise typer.Exit(EXIT_NO_RESULT)

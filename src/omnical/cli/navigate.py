"""``omnical navigate``: plan and drive legs between points, on the twin or a real robot.

On the twin (``--world``) and on a ROS 2 robot with ``/scan`` the legs are localised by
scan-to-map matching; over serial by odometry fused with the hedgehog's fixes (docs/HARDWARE.md).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.cli.errors import EXIT_NO_RESULT, handled_errors
from omnical.cli.monitor_options import MonitorOption, monitor_link
from omnical.cli.options import Overwrite, Seed
from omnical.cli.output import say
from omnical.cli.robot_target import TwistStamped
from omnical.cli.serial_options import (
    AreaOption,
    Baud,
    HedgeBaud,
    HostWatchdog,
    LiveOptions,
    MapBeacons,
    Margin,
    Model,
    RobotOption,
    TimeScale,
    Yes,
    confirm_first_motion,
)

if TYPE_CHECKING:
    from collections.abc import Sequence

    import numpy as np
    from numpy.typing import NDArray

    from omnical.cli.robot_target import HedgeTarget, RobotTarget
    from omnical.drivers.safety import PathCheck
    from omnical.navigation.grid import OccupancyGrid
    from omnical.robot.description import RobotDescription
    from omnical.services.navigation import NavigationLeg
    from omnical.web.tee import MonitorLink

__all__ = ["navigate"]


def navigate(
    map_yaml: Annotated[
        Path,
        typer.Option(
            "--map",
            help="Map to plan and localise on: map_server YAML, or a shipped world "
            "(lab-8x6, warehouse-20x20).",
        ),
    ],
    start: Annotated[
        str,
        typer.Option(metavar="X,Y,YAW", help="Start pose (m, m, rad; or YAW as 90deg), map frame."),
    ],
    goal: Annotated[
        list[str], typer.Option(metavar="X,Y", help="Goal (m); repeat for several legs.")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Bag of the run (odometry, truth).")],
    world: Annotated[
        Path | None,
        typer.Option(
            help="Floor plan the twin drives in: map_server YAML, or a shipped world "
            "(lab-8x6, warehouse-20x20). Required on the twin; not on a real robot."
        ),
    ] = None,
    robot: RobotOption = "rosy-mecanum",
    model: Model = None,
    hedge: Annotated[
        str | None,
        typer.Option(
            help="The Marvelmind hedgehog on a real robot: 'serial:PORT', or 'topic:/NAME' (ROS 2)."
        ),
    ] = None,
    beacons: MapBeacons = None,
    seed: Seed = 0,
    overwrite: Overwrite = False,
    controller: Annotated[
        list[str] | None,
        typer.Option(
            help="Controller of the legs: waypoint (seed 001: turn, then drive) or tracking "
            "(holonomic tracker); once for every leg, or once per --goal.",
        ),
    ] = None,
    baud: Baud = 115200,
    hedge_baud: HedgeBaud = 115200,
    margin: Margin = 0.3,
    area: AreaOption = None,
    host_watchdog: HostWatchdog = 0.5,
    yes: Yes = False,
    time_scale: TimeScale = 1.0,
    monitor: MonitorOption = None,
    twist_stamped: TwistStamped = False,
) -> None:
    """Navigate between points: PRM legs, seed 001's way-point controller or the holonomic
    tracker; on the twin with scan-to-map localisation (writes the bag with /scan and NAV.png),
    on a ROS 2 robot localised on its /scan (else as over serial), or on a robot over serial
    localised by odometry + hedgehog fixes (writes the bag)."""
    with handled_errors():  # before the monitor link, which would reset the page
        live = LiveOptions(
            baud, hedge_baud, margin, area, 0.0, host_watchdog, yes, time_scale, twist_stamped
        )
    with handled_errors(), monitor_link(monitor, "omnical navigate") as link:
        from omnical.cli.robot_target import (
            HedgeTarget,
            check_live_options,
            parse_hedge,
            parse_robot_target,
        )
        from omnical.errors import ConfigError

        target = parse_robot_target(robot, model)
        if not target.is_live:
            if world is None:
                msg = "--world is required on the twin (the floor plan it drives in)"
                raise ConfigError(msg)
            twin_takes = LiveOptions(baud, hedge_baud, host_watchdog_s=host_watchdog, yes=yes)
            if hedge is not None or live != twin_takes:  # the rest is a real robot's
                msg = (
                    "--hedge, --area, --margin, --time-scale and --twist-stamped apply to a real "
                    "robot only (--robot serial:PORT or ros2)"
                )
                raise ConfigError(msg)
            _navigate(
                world, map_yaml, start, goal, out, target.model, seed, overwrite, controller or [],
                link,
            )  # fmt: skip
            return
        if world is not None:
            msg = "--world is the twin's floor plan: a real robot drives in the real one"
            raise ConfigError(msg)
        chosen = parse_hedge(hedge) if hedge is not None else HedgeTarget("none")
        if target.is_serial and chosen.port is None:
            msg = "--robot serial:PORT localises on the hedgehog: give --hedge serial:PORT"
            raise ConfigError(msg)
        if chosen.kind == "none" and beacons is None and area is not None:
            msg = (
                "--area is checked with the beacon coverage: without a hedgehog give --beacons "
                "too, or leave --area out"
            )
            raise ConfigError(msg)
        check_live_options(target, chosen, twist_stamped, beacons)
        _navigate_live(
            map_yaml, start, goal, out, target, chosen, beacons, overwrite, controller or [], live,
            link,
        )  # fmt: skip


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
    link: MonitorLink | None = None,
) -> None:
    from dataclasses import replace

    from omnical.bags.bag import bag_location, check_bag_output, partial_location, write_bag
    from omnical.cli.monitor_options import tee_to
    from omnical.cli.progress import DistanceTally, run_progress
    from omnical.errors import SafetyStopError
    from omnical.recording.recording import RecordingBuilder
    from omnical.reports.navigation import write_navigation_figure
    from omnical.reports.outputs import claim_files
    from omnical.services.navigation import navigate as run_navigation
    from omnical.services.navigation import robot_world
    from omnical.twin.params import default_twin
    from omnical.twin.world import check_start

    target = check_bag_output(out, overwrite=overwrite)
    figure = target.with_name(target.name.removesuffix(".bag") + ".png")
    claim_files([figure], overwrite=overwrite)
    pose, targets, choices, description, map_grid = _legs(
        map_yaml, start, goals, controllers, robot
    )
    params = replace(default_twin(description), start_pose_map=pose)
    w = robot_world(world_yaml, description)
    check_start(w, pose, "--start", "give a free --start")
    builder = RecordingBuilder()
    _latch_map(link, map_grid, pose, None)
    try:
        tally = DistanceTally(tee_to(builder, link))
        with run_progress(f"{len(targets)} leg(s)", tally, link) as update:  # robot time
            tally.on_update = lambda t_s: update(t_s, 0.0)
            shown = [0.0]

            def on_time(t_s: float) -> None:  # the twin's rows come at its end: its clock
                if t_s >= shown[0] + 0.5:
                    shown[0] = t_s
                    update(t_s, 0.0)

            run = run_navigation(
                w,
                map_grid,
                description,
                params,
                targets,
                seed=seed,
                controller=choices,  # type: ignore[arg-type]
                sink=tally,
                on_time=on_time,
            )
    except (KeyboardInterrupt, SafetyStopError):  # the run so far is in the builder: keep it
        recording = builder.build()
        if recording.message_count:
            kept = write_bag(recording, partial_location(bag_location(out)))
            typer.echo(f"omnical: robot stopped; kept the partial run in {kept}", err=True)
        raise
    if not any(leg.control is not None for leg in run.legs):  # nothing moved: nothing to keep
        for k, leg in enumerate(run.legs, 1):
            say(f"leg {k} to {leg.goal_m}: plan {leg.plan.status}: {leg.plan.reason}")
        say("the robot did not move; no bag written")
        raise typer.Exit(EXIT_NO_RESULT)
    written = write_bag(builder.build(), out, overwrite=overwrite)
    write_navigation_figure(run, map_grid, figure, f"navigate on {map_yaml.name}")
    _say_legs(run.legs)
    if run.collision:
        say(run.collision)
    if run.localisation_accepted < MIN_ACCEPTED_MATCHES:
        typer.echo(
            f"omnical: warning: the scans matched --map {map_yaml} only "
            f"{run.localisation_accepted * 100:.0f} % of the time: is it a map of --world "
            f"{world_yaml}?",
            err=True,
        )
    say(f"min clearance {run.min_clearance_m * 100:.1f} cm; wrote {written} and {figure}")
    if not run.reached:
        raise typer.Exit(EXIT_NO_RESULT)


MIN_ACCEPTED_MATCHES = 0.9
"""Below this share of scan-to-map matches accepted, navigate on the twin warns: its map and
world disagree (the lab world on its own map and on its SLAM map: 100 %; on the warehouse
world: 72 %)."""


def _controller_list(controllers: list[str], legs: int) -> list[str]:
    """The controller of every leg (empty: the default), checked."""
    from omnical.errors import ConfigError

    for c in controllers:
        if c not in ("waypoint", "tracking"):
            msg = f"--controller: {c!r} is not one of waypoint, tracking"
            raise ConfigError(msg)
    if len(controllers) not in (0, 1, legs):
        msg = (
            f"--controller: give it once or once per --goal ({legs}), not {len(controllers)} times"
        )
        raise ConfigError(msg)
    return controllers * legs if len(controllers) == 1 else controllers


def _legs(
    map_yaml: Path, start: str, goals: list[str], controllers: list[str], model: str
) -> tuple[
    tuple[float, float, float],
    list[tuple[float, float]],
    list[str],
    RobotDescription,
    OccupancyGrid,
]:
    """The start pose, the goals and their controllers, the robot and the map, checked."""
    from omnical.cli.plan import check_inside, parse_xy
    from omnical.cli.robot_target import load_said_robot
    from omnical.navigation.map_io import load_map, resolve_world

    pose = parse_xy(start, "--start", 3)
    targets = [(t[0], t[1]) for t in (parse_xy(g, "--goal") for g in goals)]
    choices = _controller_list(controllers, len(targets)) or ["waypoint"] * len(targets)
    description = load_said_robot(model)
    map_grid = load_map(resolve_world(map_yaml))
    check_inside(map_grid, "--start", pose, map_yaml)
    for xy in targets:
        check_inside(map_grid, "--goal", xy, map_yaml)
    return (pose[0], pose[1], pose[2]), targets, choices, description, map_grid


def _say_legs(legs: Sequence[NavigationLeg]) -> None:
    """One line a leg: its plan, how its loop ended, its goal error (the truth's on a twin,
    else the localised pose's)."""
    import math

    for k, leg in enumerate(legs, 1):
        state = leg.control.reason if leg.control is not None else "-"
        error = (
            f"goal error {leg.goal_error_m * 100:.1f} cm"
            if math.isfinite(leg.goal_error_m) or leg.control is None
            else f"goal error by the localised pose {leg.estimated_error_m * 100:.1f} cm"
        )
        say(
            f"leg {k} to {leg.goal_m} ({leg.controller}): plan {leg.plan.status} "
            f"({leg.plan.method or leg.plan.reason}), control {state}, {error}"
        )


def _navigate_live(
    map_yaml: Path,
    start: str,
    goals: list[str],
    out: Path,
    target: RobotTarget,
    hedge: HedgeTarget,
    beacons: str | None,
    overwrite: bool,
    controllers: list[str],
    live: LiveOptions,
    link: MonitorLink | None = None,
) -> None:
    """The legs on a real robot: open, locate, plan and check every leg, confirm, drive.

    Localised by scan-to-map matching on a robot with a LiDAR (a ROS 2 robot's ``/scan``),
    else by odometry fused with the hedgehog's fixes. With a hedgehog the start is checked
    against it and every leg against the beacon coverage."""
    import math

    import numpy as np

    from omnical.bags.bag import check_bag_output
    from omnical.bags.recorder import BagRecorder
    from omnical.cli.monitor_options import driver_status, tee_to
    from omnical.cli.progress import DistanceTally, run_progress
    from omnical.cli.robot_target import live_rig
    from omnical.cli.serial_options import ABORT_KEYS_TEXT, map_beacons
    from omnical.control.limits import DEFAULT_COMMAND_LIMITS, CommandLimits
    from omnical.errors import ConfigError, LimitError
    from omnical.estimation.fusion import FusionParams
    from omnical.navigation.inflation import inflate
    from omnical.navigation.prm import PlanParams, build_roadmap, plan
    from omnical.services.hil import hedgehog_start
    from omnical.services.navigation import navigate_on, robot_footprint
    from omnical.services.path_checks import check_polyline

    check_bag_output(out, overwrite=overwrite)
    pose, targets, choices, description, map_grid = _legs(
        map_yaml, start, goals, controllers, target.model
    )
    allowed, margin = live.allowed, live.margin_m
    bmap = map_beacons(beacons)
    infl = inflate(map_grid, footprint=robot_footprint(description))
    params = PlanParams()
    roadmap = build_roadmap(infl, params.prm)
    with live_rig(target, hedge, description, live, flush_every_s=0.05 if link else 0.5) as rig:
        hedgehog, on_scan = rig.hedge, rig.lidar is not None
        if hedgehog is None and not on_scan:
            msg = (
                "the robot publishes no /scan to localise on: give the hedgehog, "
                "--hedge serial:PORT or topic:/NAME"
            )
            raise ConfigError(msg)
        why_not = "there is no live LiDAR driver" if target.is_serial else "no /scan"
        how = (
            f"its odometry corrected by scan-to-map matching of its LiDAR on {map_yaml}"
            if on_scan
            else f"odometry fused with the hedgehog's fixes (no scan matching: {why_not})"
        )
        say(f"{description.name} {target.where}, localised by {how}")
        here = pose[:2]
        if hedgehog is not None:
            bmap, at_rest = hedgehog_start(description, hedgehog, bmap, rig.clock, pose[2])
            here = at_rest[:2]
            off = math.hypot(here[0] - pose[0], here[1] - pose[1])
            if off > 0.3:
                msg = (
                    f"the hedgehog puts the robot at ({here[0]:.2f}, {here[1]:.2f}) m, {off:.2f} "
                    f"m from --start ({pose[0]:.2f}, {pose[1]:.2f}): a wrong start, or the "
                    "beacon map's frame is not the map's"
                )
                raise LimitError(msg)
        frm = np.array(pose[:2] if on_scan else here)
        least = math.inf
        for k, (goal, choice) in enumerate(zip(targets, choices, strict=True), 1):
            res = plan(infl, frm, np.array(goal), params, roadmap=roadmap)
            if res.status != "ok":
                say(f"leg {k} to {goal}: plan {res.status}: {res.reason}")
                say("the robot did not move; no bag written")
                raise typer.Exit(EXIT_NO_RESULT)
            if bmap is not None:
                verdict = check_polyline(
                    res.path_m, bmap, margin_m=margin, allowed=allowed,
                    name=f"leg {k} to ({goal[0]:.2f}, {goal[1]:.2f})",
                )  # fmt: skip
                if not verdict.ok:
                    raise LimitError(f"refused: {verdict.reason}")
                least = min(least, verdict.coverage_margin_m)
            say(f"leg {k} to {goal} ({choice}): plan ok ({res.method}), {len(res.path_m)} points")
            frm = np.array(goal)
        if bmap is not None:
            say(
                f"start ({here[0]:.2f}, {here[1]:.2f}) m by the hedgehog; every leg at least "
                f"{least:.2f} m inside the beacon coverage"
            )
        else:
            say("no hedgehog: the legs are checked against the map only (planned clear of it)")
        question = f"drive {len(targets)} leg(s) on the robot now? ({ABORT_KEYS_TEXT})"
        if not confirm_first_motion(question, live.yes):
            return
        _latch_map(link, map_grid, (here[0], here[1], pose[2]), bmap, description.hedge_offset_m)
        limits = CommandLimits.from_robot(description.limits).tightened(DEFAULT_COMMAND_LIMITS)
        fusion = FusionParams(
            hedge_offset_m=(description.hedge_offset_m[0], description.hedge_offset_m[1])
        )
        coverage = bmap

        def check_leg(path_m: NDArray[np.float64], goal: tuple[float, float]) -> PathCheck:
            assert coverage is not None
            name = f"the leg to ({goal[0]:.2f}, {goal[1]:.2f})"
            return check_polyline(path_m, coverage, margin_m=margin, allowed=allowed, name=name)

        legs_done: list[NavigationLeg] = []

        def leg_done(leg: NavigationLeg) -> None:
            legs_done.append(leg)
            line = f"leg {len(legs_done)}/{len(targets)} to {leg.goal_m}: ended"
            if link is not None:
                link.event(line)

        with (
            BagRecorder(out, overwrite=overwrite) as rec,
            driver_status(link, rig.robot, live.host_watchdog_s),
        ):
            tally = DistanceTally(tee_to(rec, link))
            with run_progress(f"{len(targets)} leg(s)", tally, link) as update:
                tally.on_update = lambda t_s: update(t_s, 0.0)
                run = navigate_on(
                    rig,
                    tally,
                    targets,
                    choices,  # type: ignore[arg-type]
                    inflated=infl,
                    roadmap=roadmap,
                    plan_params=params,
                    limits=limits,
                    start_pose_map=pose,
                    map_grid=map_grid if on_scan else None,
                    fusion=None if on_scan else fusion,
                    check_leg=check_leg if coverage is not None else None,
                    on_leg=leg_done,
                )
            if run.interruption is not None:
                rig.robot.close()
                rec.close(partial=True)
                typer.echo(
                    f"omnical: robot stopped; kept the partial run in {rec.kept_at}", err=True
                )
                raise run.interruption
        _say_legs(run.legs)
        used = "scans matched" if on_scan else "hedgehog fixes"
        say(
            f"{used}: {run.accepted} used, {run.rejected} "
            f"{'rejected' if on_scan else 'gated out'}; "
            f"wrote {rec.kept_at} ({rec.message_count} messages)"
        )
        if not run.reached:
            why = run.stopped_because or "a leg was not completed"
            typer.echo(f"omnical: not every goal was reached: {why}", err=True)
            raise typer.Exit(EXIT_NO_RESULT)


def _latch_map(
    link: MonitorLink | None,
    grid: OccupancyGrid,
    start: tuple[float, float, float],
    beacons: object | None,
    hedge_offset_m: tuple[float, ...] | None = None,
) -> None:
    """With ``--monitor``: the map under the view, the start pose, the beacons."""
    if link is None:
        return
    from omnical.cli.monitor_options import latch_scene
    from omnical.web.protocol import map_payload

    link.latch("map", map_payload(grid.cells, grid.resolution_m, grid.origin))
    latch_scene(link, beacons=beacons, start_pose_map=start, hedge_offset_m=hedge_offset_m)

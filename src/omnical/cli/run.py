"""``omnical run``: one motion script or controller task, on the in-process twin or a robot.

On a robot (``--robot serial:PORT`` or ``ros2``) it runs in wall-clock time, recorded as it goes,
after the checks of docs/HARDWARE.md; a task prints seed 003's measures.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.monitor_options import (
    MonitorOption,
    driver_status,
    latch_scene,
    monitor_link,
    tee_to,
)
from omnical.cli.options import Overwrite, Seed
from omnical.cli.output import say
from omnical.cli.robot_target import TwistStamped
from omnical.cli.serial_options import (
    ABORT_KEYS_TEXT,
    AreaOption,
    Baud,
    HedgeBaud,
    HostWatchdog,
    LiveOptions,
    MapBeacons,
    Margin,
    Model,
    RobotOption,
    StartYaw,
    TimeScale,
    Yes,
    confirm_first_motion,
    map_beacons,
)

if TYPE_CHECKING:
    from omnical.bags.recorder import BagRecorder
    from omnical.cli.robot_target import HedgeTarget, RobotTarget
    from omnical.control.rig_loop import ControlRig
    from omnical.experiment.library import BuiltinTask
    from omnical.experiment.rig import Rig
    from omnical.experiment.script import MotionScript
    from omnical.ips.beacons import BeaconMap
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.robot.description import RobotDescription
    from omnical.twin.params import TwinParams
    from omnical.twin.rig import TwinRig
    from omnical.web.tee import MonitorLink

__all__ = ["run"]


def run(
    script: Annotated[
        str,
        typer.Argument(
            help="Motion script YAML, a built-in script (straight-10m, tour, lab-tour) or a built-in "
            "controller task (seed003-centred-turning, seed003-driving-forward, seed003-square, "
            "seed003-triangle)."
        ),
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Recording to write: RUN.mcap.")],
    robot: RobotOption = "twin",
    hedge: Annotated[
        str,
        typer.Option(
            help="'twin', 'serial:PORT' (Marvelmind hedgehog), 'topic:/NAME' (ROS 2 "
            "PointStamped or PoseWithCovarianceStamped) or 'none'."
        ),
    ] = "twin",
    model: Model = None,
    twin: Annotated[str, typer.Option(help="In-process twin: YAML, 'default' or 'ideal'.")] = (
        "default"
    ),
    seed: Seed = 0,
    beacons: MapBeacons = None,
    baud: Baud = 115200,
    hedge_baud: HedgeBaud = 115200,
    factors: Annotated[
        Path | None,
        typer.Option(
            help="factors.yaml to compensate with: host-side on a serial robot (stock "
            "firmware), in the vehicle controller on the twin."
        ),
    ] = None,
    margin: Margin = 0.3,
    area: AreaOption = None,
    start_yaw: StartYaw = 0.0,
    host_watchdog: HostWatchdog = 0.5,
    yes: Yes = False,
    overwrite: Overwrite = False,
    time_scale: TimeScale = 1.0,
    monitor: MonitorOption = None,
    twist_stamped: TwistStamped = False,
) -> None:
    """Run a motion script or a seed 003 test on the twin or a robot (serial, ROS 2); record it."""
    with handled_errors():  # before the monitor link, which would reset the page
        live = LiveOptions(
            baud, hedge_baud, margin, area, start_yaw, host_watchdog, yes, time_scale, twist_stamped
        )
    with handled_errors(), monitor_link(monitor, "omnical run") as link:
        from omnical.bags.bag import check_bag_output
        from omnical.cli.robot_target import (
            check_live_options,
            load_said_robot,
            parse_hedge,
            parse_robot_target,
        )
        from omnical.errors import ConfigError
        from omnical.experiment.library import builtin_task
        from omnical.experiment.script import load_script

        target = parse_robot_target(robot, model)
        hedge_target = parse_hedge(hedge)
        task = builtin_task(script)
        if not target.is_live:
            live.refuse_on_twin("--robot twin")
        if hedge_target.kind == "none" and live.area is not None:
            msg = (
                "--area needs the hedgehog: without it the path cannot be placed in the map, so it "
                "cannot be checked against the area (give --hedge, or leave --area out)"
            )
            raise ConfigError(msg)
        check_live_options(target, hedge_target, live.twist_stamped, beacons)
        _check_script_name(script)
        check_bag_output(out, overwrite=overwrite)
        description = load_said_robot(target.model)
        compiled = None if task is not None else load_script(script, description.limits)
        bmap = map_beacons(beacons)
        if target.is_live:
            job = compiled if task is None else task
            _run_live(
                job, description, target, hedge_target, bmap, out, overwrite, factors, live, link
            )
            return
        rig, installed = _twin_rig(description, twin, seed, bmap, factors)
        shown = bmap or map_beacons("default")
        latch_scene(link, beacons=shown, start_pose_map=rig.params.start_pose_map,
                    hedge_offset_m=description.hedge_offset_m)  # fmt: skip
        if task is not None:
            say(_task_line(task, description, rig))
            say(f"wheel loop: {_wheel_loop_text(rig.params)}")
            _record_task(rig, task, description, out, overwrite, installed, link=link)
        else:
            assert compiled is not None
            _record_script(rig, compiled, out, overwrite, installed, link)


def _check_script_name(script: str) -> None:
    """Refuse a name that is neither a file nor a built-in script or task, listing both."""
    from omnical.errors import ConfigError
    from omnical.experiment.library import builtin_script_names, builtin_task_names

    p = Path(script)
    if p.exists() or p.suffix or script in builtin_script_names() + builtin_task_names():
        return
    msg = (
        f"{script}: no such script file, and not a built-in script "
        f"({', '.join(builtin_script_names())}) or controller task "
        f"({', '.join(builtin_task_names())})"
    )
    raise ConfigError(msg)


def _wheel_loop_text(params: TwinParams) -> str:
    from omnical.twin.params import OMNI_X_WHEEL_PID

    pid = params.wheel_pid
    if pid is None:
        return "the twin's PI + feed-forward wheel loop (no seed 003 tuning installed)"
    origin = (
        " (seed 003 Ziegler–Nichols at 100 rpm, Tyreus–Luyben refinement)"
        if pid == OMNI_X_WHEEL_PID
        else ""
    )
    return (
        f"wheel-speed PID Kp {pid.kp:.3f}, Ti {pid.ti_s * 1e3:.1f} ms, "
        f"Td {pid.td_s * 1e3:.2f} ms{origin}"
    )


def _twin_rig(
    description: RobotDescription,
    twin: str,
    seed: int,
    bmap: BeaconMap | None,
    factors: Path | None,
) -> tuple[TwinRig, CorrectionFactors | None]:
    """The in-process twin as a rig, and the factors its vehicle controller is to compensate with."""
    from omnical.calibration.factors_io import read_factors
    from omnical.twin.params import load_twin
    from omnical.twin.rig import TwinRig

    params = load_twin(twin, description, bmap)
    installed = None
    if factors is not None:  # the twin's vehicle controller compensates, as reflashed firmware
        installed = read_factors(factors).factors
        say(f"installed {factors} in the twin's vehicle controller")
    return TwinRig(description, params, seed=seed, beacons=bmap), installed


def _record_script(
    rig: Rig,
    script: MotionScript,
    out: Path,
    overwrite: bool,
    installed: CorrectionFactors | None = None,
    link: MonitorLink | None = None,
) -> None:
    """Run ``script`` on ``rig`` into a bag flushed as it goes; a stopped run is kept as
    ``RUN.partial`` and its cause re-raised (Ctrl-C 130, SIGTERM 143, a safety stop 4)."""
    from omnical.bags.recorder import BagRecorder
    from omnical.cli.progress import DistanceTally, run_progress
    from omnical.experiment.rig import run_script_on

    with BagRecorder(out, overwrite=overwrite) as rec:
        tally = DistanceTally(tee_to(rec, link))
        try:
            with run_progress(script.name, tally, link) as update:
                log = run_script_on(
                    rig, script, tally, installed=installed, record_installed=True, on_tick=update
                )
        except BaseException:  # a stop outside the run's own handling (its start, its end)
            _kept_partial(rec)
            raise
        if log.interrupted:
            if link is not None:  # the page hears it now, before the bag is closed
                why = str(log.interruption) or type(log.interruption).__name__
                if isinstance(log.interruption, KeyboardInterrupt):
                    why = "stopped by the user (q or Ctrl-C)"
                link.event(f"robot stopped: {why}; keeping the partial run")
            rec.close(partial=True)
            typer.echo(f"omnical: robot stopped; kept the partial run in {rec.kept_at}", err=True)
            raise log.interruption or KeyboardInterrupt()
    say(f"wrote {rec.kept_at} ({rec.message_count} messages)")


def _kept_partial(rec: BagRecorder) -> None:
    """The run stopped outside its own handling of a stop: kept as ``RUN.partial``, said."""
    rec.close(partial=True)
    typer.echo(f"omnical: robot stopped; kept the partial run in {rec.kept_at}", err=True)


def _task_line(
    task: BuiltinTask, description: RobotDescription, rig: ControlRig, where: str = "over serial"
) -> str:
    """What closes a task's loop on ``rig`` (``where`` the robot is), in one printed line."""
    from omnical.services.seed003 import task_pose_source

    ros2 = where == "over ROS 2"
    where = "" if "seed003" in rig.sources else f" {where}"
    if "seed003" in rig.sources and task_pose_source(description) == "seed003":
        closes = (
            f"the seed 003 estimate ({len(description.dead_wheels)} dead wheels + IMU yaw + "
            "magnetometer)"
        )
    elif "seed003" in rig.sources:
        closes = "its wheel odometry (no dead wheels: the seed 003 estimate needs three)"
    else:
        seed003 = ", not the seed 003 estimate its twin would close on"
        how = (
            "its ROS 2 driver's odometry (on /odom; a ROS 2"
            if ros2
            else "the vehicle controller's odometry (integrated from its status frames; a serial"
        )
        closes = (
            f"{how} robot has no dead-wheel topics"
            f"{seed003 if len(description.dead_wheels) >= 3 else ''})"
        )
    return f"{task.name}: {task.title} on {description.name}{where}, closed on {closes}"


def _record_task(
    rig: ControlRig,
    task: BuiltinTask,
    description: RobotDescription,
    out: Path,
    overwrite: bool,
    installed: CorrectionFactors | None,
    start_pose_map: tuple[float, float, float] | None = None,
    link: MonitorLink | None = None,
) -> None:
    """The task's controller in closed loop on ``rig``, into a bag flushed as it goes; the
    paper's measures on the closing pose (and the truth on a twin). A stopped run is kept as
    ``RUN.partial`` and its cause re-raised; a loop that did not reach its goal exits 3."""
    from omnical.bags.recorder import BagRecorder
    from omnical.cli.errors import EXIT_NO_RESULT
    from omnical.cli.progress import DistanceTally, run_progress
    from omnical.paper import SEED003_PAPER_TEST_ERRORS
    from omnical.services.seed003 import ERROR_LABELS, run_task_on
    from omnical.twin.rig import TwinRig

    if start_pose_map is None and isinstance(rig, TwinRig):
        start_pose_map = tuple(float(v) for v in rig.params.start_pose_map)  # type: ignore[assignment]
    with BagRecorder(out, overwrite=overwrite) as rec:
        tally = DistanceTally(tee_to(rec, link))
        try:
            with run_progress(task.name, tally, link) as update:
                done = run_task_on(
                    rig, task, description, tally, installed=installed,
                    start_pose_map=start_pose_map or (0.0, 0.0, 0.0),
                    on_tick=lambda t_s, _out: update(t_s, 0.0),
                )  # fmt: skip
        except BaseException:  # a stop outside the loop's own handling (its start, its end)
            _kept_partial(rec)
            raise
        control = done.run.control
        if done.run.interrupted:
            rec.close(partial=True)
            if link is not None:
                link.event("robot stopped: the task was interrupted; partial run kept")
            typer.echo(
                f"omnical: robot stopped; kept the partial run in {rec.kept_at} "
                f"({control.t_s[-1] - control.t_s[0]:.1f} s of the loop)",
                err=True,
            )
            raise control.interruption or KeyboardInterrupt()
    say(f"loop ended: {control.reason} after {control.t_s[-1] - control.t_s[0]:.1f} s")
    est, truth = done.estimate_errors, done.truth_errors
    source = "estimate" if done.pose == "seed003" else "odometry"
    if est is not None and control.reason == "done":
        paper = SEED003_PAPER_TEST_ERRORS[task.slug]
        for i, (label, p) in enumerate(zip(ERROR_LABELS[task.slug], paper, strict=True)):
            e = (est.first, est.second)[i]
            if truth is None:
                say(f"{label}: {source} {e:.2f}, paper {p:g} (ground truth: on a twin only)")
            else:
                g = (truth.first, truth.second)[i]
                say(f"{label}: {source} {e:.2f}, ground truth {g:.2f}, paper {p:g}")
    say(f"wrote {rec.kept_at} ({rec.message_count} messages)")
    if control.reason != "done":
        why = done.run.stopped_because or f"the loop ended on {control.reason}"
        typer.echo(f"omnical: the task was not completed: {why}", err=True)
        raise typer.Exit(EXIT_NO_RESULT)


def _run_live(
    job: object,
    description: object,
    target: RobotTarget,
    hedge: HedgeTarget,
    bmap: BeaconMap | None,
    out: Path,
    overwrite: bool,
    factors: Path | None,
    live: LiveOptions,
    link: MonitorLink | None = None,
) -> None:
    """A motion script or a controller task (``job``) on a real robot (serial or ROS 2):
    open, check, confirm, run."""

    from omnical.calibration.factors_io import read_factors
    from omnical.cli.output import also_told
    from omnical.cli.output import warn as warn_line
    from omnical.cli.robot_target import live_rig
    from omnical.drivers.safety import check_path
    from omnical.errors import LimitError
    from omnical.experiment.library import BuiltinTask
    from omnical.experiment.script import MotionScript
    from omnical.robot.description import RobotDescription
    from omnical.services.hil import hedgehog_start
    from omnical.services.path_checks import check_task_path

    assert isinstance(job, MotionScript | BuiltinTask)
    assert isinstance(description, RobotDescription)
    allowed, yes = live.allowed, live.yes
    comp = read_factors(factors).factors if factors is not None else None
    warn = also_told(warn_line, link, "warning: ")
    with live_rig(target, hedge, description, live, on_warning=warn) as rig:
        hedgehog = rig.hedge
        if isinstance(job, BuiltinTask):
            say(_task_line(job, description, rig, target.where))
        if hedgehog is not None:
            bmap, start = hedgehog_start(description, hedgehog, bmap, rig.clock, live.start_yaw_rad)
            latch_scene(link, beacons=bmap, start_pose_map=start,
                        hedge_offset_m=description.hedge_offset_m)  # fmt: skip
            if isinstance(job, BuiltinTask):
                verdict = check_task_path(
                    job.reference_m, start, bmap, margin_m=live.margin_m, allowed=allowed,
                    name=job.name,
                )  # fmt: skip
            else:
                verdict = check_path(job, start, bmap, margin_m=live.margin_m, allowed=allowed)
            if not verdict.ok:
                raise LimitError(f"refused: {verdict.reason}")
            say(
                f"path checked from ({start[0]:.2f}, {start[1]:.2f}) m: "
                f"{verdict.coverage_margin_m:.2f} m inside the beacon coverage"
            )
        elif not yes:
            say("no hedgehog: the path cannot be checked against the beacon coverage")
        what = (
            f"the {job.name!r} controller"
            if isinstance(job, BuiltinTask)
            else f"{job.name!r} ({job.duration_s:.1f} s)"
        )
        if not confirm_first_motion(f"run {what} on the robot now? ({ABORT_KEYS_TEXT})", yes):
            return
        if link is not None:
            rig.flush_every_s = 0.05  # the monitor's view at the status stream's 20 Hz
        with driver_status(link, rig.robot, live.host_watchdog_s):
            if isinstance(job, BuiltinTask):
                _record_task(rig, job, description, out, overwrite, comp, link=link)
            else:
                _record_script(rig, job, out, overwrite, comp, link)

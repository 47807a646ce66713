"""``omnical calibrate campaign``: seed 000's procedures (Figure 7) run on the twin or a robot.

Writes factors, header, ROS parameters, report, figures and recordings under ``--out``; one flow
(:func:`_campaign`) for every robot, only the bench differs. On a robot: docs/HARDWARE.md.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import EstimationMethod, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.monitor_options import MonitorOption, driver_status, monitor_link
from omnical.cli.options import BeaconMapOption, Installed, Method, Overwrite, Seed
from omnical.cli.robot_target import TwistStamped
from omnical.cli.serial_options import (
    AreaOption,
    Baud,
    HedgeBaud,
    HostWatchdog,
    LiveOptions,
    Margin,
    Model,
    RobotOption,
    StartYaw,
    TimeScale,
    Yes,
    check_can_confirm,
    confirm_first_motion,
)

if TYPE_CHECKING:
    from omnical.calibration.campaign import Bench, CampaignProgress, CampaignResult, Iteration
    from omnical.cli.robot_target import HedgeTarget, RobotTarget
    from omnical.drivers.safety import Area
    from omnical.ips.beacons import BeaconMap
    from omnical.kinematics.correction import CorrectionFactors
    from omnical.recording.recording import Recording
    from omnical.robot.description import RobotDescription
    from omnical.web.tee import MonitorLink

__all__ = ["campaign"]

MAX_ITERATIONS = 100
"""Most iterations --max-iterations allows: the flowchart settles in a handful (seed 000: 3)."""


def _check_tolerances(scale_percent: float, crosstalk_mrad_per_m: float) -> None:
    """Refuse a tolerance that is not a finite number > 0, naming the option as typed."""
    from omnical.errors import ConfigError

    for option, value, unit in (
        ("--tolerance-scale", scale_percent, "%"),
        ("--tolerance-crosstalk", crosstalk_mrad_per_m, "mrad/m"),
    ):
        if not (math.isfinite(value) and value > 0.0):
            msg = f"{option} {value:g}: must be a finite number > 0 ({unit})"
            raise ConfigError(msg)


def campaign(
    robot: RobotOption = "twin",
    model: Model = None,
    hedge: Annotated[
        str,
        typer.Option(
            help="'twin' (with --robot twin) or 'serial:PORT' (the hedgehog, on a robot)."
        ),
    ] = "twin",
    twin: Annotated[
        str, typer.Option(help="The robot's digital twin: twin YAML, or 'default' / 'ideal'.")
    ] = "default",
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output directory (factors, report, figures, bags).")
    ] = Path("omnical-calibration"),
    seed: Seed = 0,
    method: Method = EstimationMethod.PROCEDURES.value,
    max_iterations: Annotated[
        int,
        typer.Option(
            help=f"Most iterations of the flowchart (1 to {MAX_ITERATIONS}).",
            min=1,
            max=MAX_ITERATIONS,
        ),
    ] = 4,
    tolerance_scale: Annotated[
        float, typer.Option(help="Stop when no scaling changes by more (%).")
    ] = 0.3,
    tolerance_crosstalk: Annotated[
        float, typer.Option(help="... and no cross-talk by more (mrad/m).")
    ] = 1.0,
    installed: Installed = None,
    beacons: BeaconMapOption = None,
    overwrite: Overwrite = False,
    baud: Baud = 115200,
    hedge_baud: HedgeBaud = 115200,
    margin: Margin = 0.3,
    area: AreaOption = None,
    start_yaw: StartYaw = 0.0,
    home: Annotated[
        bool, typer.Option(help="On a robot: drive back to the start between runs.")
    ] = True,
    host_watchdog: HostWatchdog = 0.5,
    yes: Yes = False,
    figures: Annotated[bool, typer.Option(help="Draw the report's figures.")] = True,
    validate: Annotated[
        bool, typer.Option(help="Run the validation procedures after the iterations.")
    ] = True,
    time_scale: TimeScale = 1.0,
    monitor: MonitorOption = None,
    twist_stamped: TwistStamped = False,
) -> None:
    """Run seed 000's calibration procedures on a robot: its twin, over serial ports or ROS 2.

    Iterates until the factors settle, validates, measures before and after (twin only), prints
    the factors and the measures, and writes factors.yaml, omnical_factors.h,
    wheeltec_params.yaml, report.md, figures/ and recordings/ in OUT.
    """
    with handled_errors():  # before the monitor link, which would reset the page
        live = LiveOptions(
            baud, hedge_baud, margin, area, start_yaw, host_watchdog, yes, time_scale, twist_stamped
        )
    with handled_errors(), monitor_link(monitor, "omnical calibrate campaign") as link:
        from omnical.calibration.campaign import CampaignProgress, Tolerance, run_campaign
        from omnical.calibration.factors_io import read_factors
        from omnical.cli.calibrate_output import print_campaign
        from omnical.cli.output import tell
        from omnical.cli.progress import campaign_progress
        from omnical.cli.robot_target import load_said_robot, parse_robot_target
        from omnical.errors import ConfigError
        from omnical.ips.beacons import load_beacon_map
        from omnical.reports.outputs import claim_directory

        # check, set up the bench (the twin, or the real robot checked and confirmed), run the
        # campaign, write OUT whole
        chosen = parse_choice(EstimationMethod, method, "--method")
        _check_tolerances(tolerance_scale, tolerance_crosstalk)
        target = parse_robot_target(robot, model)
        if out.suffix in {".yaml", ".yml"}:
            msg = f"--out {out}: the campaign writes a directory; give a directory name"
            raise ConfigError(msg)
        hedge_target = _check_robot_options(target, hedge, live)
        description = load_said_robot(target.model)
        allowed = live.allowed
        start = read_factors(installed).factors if installed is not None else None
        bmap = load_beacon_map(beacons) if beacons is not None else None
        tolerance = Tolerance(tolerance_scale / 100.0, tolerance_crosstalk / 1e3)
        claim_directory(out, overwrite=overwrite, writer="omnical calibrate campaign", notify=tell)
        started = time.perf_counter()  # the printed wall time covers running and writing
        if not target.is_live:
            setup = _twin_setup(description, twin, seed, start, bmap)
        else:
            assert hedge_target is not None
            setup = _live_setup(
                description, target, hedge_target, live, home, out, bmap, allowed, start, link
            )
        with setup as bench:
            if bench is None:  # declined before anything moved
                return
            _to_monitor(link, bench, bmap, description)
            status = driver_status(
                link if bench.driver else None, bench.driver, live.host_watchdog_s
            )
            with (
                campaign_progress() as on_progress,
                _live(link, on_progress) as (told, on_iteration),
                status,
            ):
                result = run_campaign(
                    description,
                    bench.bench,
                    seed=seed,
                    tolerance=tolerance,
                    max_iterations=max_iterations,
                    on_progress=told,
                    on_iteration=on_iteration,
                    method=chosen.value,
                    installed=bench.installed,
                    beacons=bmap,
                    validate=validate,
                    measure=bench.truth is not None,  # the measures need ground truth
                    truth=bench.truth,
                )
                bench.ran()
                written = _write_campaign(
                    result,
                    out,
                    description,
                    bmap,
                    lambda line: on_progress(CampaignProgress(line)),
                    figures=figures,
                    overwrite=overwrite,
                )
        print_campaign(result, written, command_wall_s=time.perf_counter() - started)


def _to_monitor(
    link: MonitorLink | None, bench: _Bench, beacons: BeaconMap | None, robot: RobotDescription
) -> None:
    """With ``--monitor``: the scene latched (beacons, home pose) and, over serial, every
    run's rows teed to the monitor as they come (the twin's runs are computed, not live)."""
    if link is None:
        return
    from omnical.cli.monitor_options import latch_scene, tee_to
    from omnical.ips.beacons import default_beacon_map

    plan = getattr(bench.bench, "plan", None)
    params = getattr(bench.bench, "params", None)
    start = plan.home_pose_map if plan is not None else getattr(params, "start_pose_map", None)
    shown = beacons or getattr(bench.bench, "beacons", None) or default_beacon_map()
    latch_scene(link, beacons=shown, start_pose_map=start, hedge_offset_m=robot.hedge_offset_m)
    if hasattr(bench.bench, "tee"):
        bench.bench.tee = lambda sink: tee_to(sink, link)


@contextmanager
def _live(
    link: MonitorLink | None, on_progress: Callable[[CampaignProgress], None]
) -> Iterator[tuple[Callable[[CampaignProgress], None], Callable[[Iteration], None] | None]]:
    """The progress callback, also telling the monitor each step (an event) and where it is
    (at most 5 times a second), and the iterations' factors with their 1σ."""
    if link is None:
        yield on_progress, None
        return
    last_step, last_at = [""], [0.0]

    def told(event: CampaignProgress) -> None:
        on_progress(event)
        now = time.monotonic()
        if event.step != last_step[0]:
            last_step[0] = event.step
            link.event(event.step)
        elif now - last_at[0] < 0.2 and event.done_s < event.total_s:
            return  # at most 5 a second, and a run's end always
        last_at[0] = now
        left = max(event.total_s - event.done_s, 0.0) if event.total_s > 0 else None
        link.send("progress", {"step": event.step, "done_s": event.done_s,
                               "total_s": event.total_s, "left_s": left})  # fmt: skip

    def on_iteration(it: Iteration) -> None:
        link.send(
            "factors",
            {"iteration": it.index, "values": it.factors.as_dict(), "sigma": dict(it.sigma),
             "converged": it.converged},
        )  # fmt: skip

    yield told, on_iteration


def _check_robot_options(
    target: RobotTarget, hedge: str, options: LiveOptions
) -> HedgeTarget | None:
    """The hedgehog on a real robot (None on the twin); the options that do not apply. On a
    ROS 2 robot, rclpy made loadable (see :func:`~omnical.cli.robot_target.check_live_options`)."""
    from omnical.cli.robot_target import check_live_options, parse_hedge
    from omnical.errors import ConfigError

    chosen = parse_hedge(hedge)
    if target.is_live and chosen.kind == "topic":
        msg = (
            f"--hedge topic:{chosen.topic}: the campaign multilaterates the hedgehog's raw "
            "distances, which a position topic does not carry: give --hedge serial:PORT"
        )
        raise ConfigError(msg)
    if target.is_live and chosen.port is None:
        msg = f"a campaign on --robot {target.kind} needs the hedgehog: --hedge serial:PORT"
        raise ConfigError(msg)
    check_live_options(target, chosen, options.twist_stamped)
    if target.is_live:
        check_can_confirm(options.yes)
        return chosen
    options.refuse_on_twin()
    return None


def _nothing() -> None:
    return None


@dataclass
class _Bench:
    """The campaign's bench and what it starts from; ``ran`` is called once the runs are over,
    before OUT is written; ``driver``: the serial robot's (its status for the monitor)."""

    bench: Bench
    installed: CorrectionFactors | None
    truth: CorrectionFactors | None
    ran: Callable[[], None] = _nothing
    driver: object | None = None


@contextmanager
def _twin_setup(
    robot: RobotDescription,
    twin: str,
    seed: int,
    start: CorrectionFactors | None,
    beacons: BeaconMap | None,
) -> Iterator[_Bench | None]:
    """The twin: every run a fresh twin, its truth known (the before/after measures)."""
    from omnical.twin.bench import TwinBench
    from omnical.twin.params import load_twin

    params = load_twin(twin, robot, beacons)
    params = params.with_installed(start) if start is not None else params
    yield _Bench(
        TwinBench(robot, params, seed=seed, beacons=beacons),
        params.installed_factors,
        params.true_factors,
    )


@contextmanager
def _live_setup(
    robot: RobotDescription,
    target: RobotTarget,
    hedge: HedgeTarget,
    options: LiveOptions,
    home: bool,
    out: Path,
    beacons: BeaconMap | None,
    allowed: Area | None,
    start: CorrectionFactors | None,
    link: MonitorLink | None = None,
) -> Iterator[_Bench | None]:
    """The robot over serial ports or ROS 2: opened, every procedure checked from where it
    stands, the plan said and confirmed (None: declined). A stop or an error before OUT is
    written stops the robot first and keeps the runs made in OUT.partial/recordings/."""
    from omnical.cli.output import also_told, say
    from omnical.cli.robot_target import live_rig
    from omnical.services.hil import serial_campaign_bench

    bench = None
    writing: list[bool] = []  # from then on a stop keeps the output being written as OUT.partial
    with live_rig(target, hedge, robot, options) as rig:
        driver, hedgehog = rig.robot, rig.hedge
        try:
            assert hedgehog is not None
            bench, _ = serial_campaign_bench(
                robot,
                driver,
                hedgehog,
                beacons=beacons,
                start_yaw_rad=options.start_yaw_rad,
                margin_m=options.margin_m,
                allowed=allowed,
                home=home,
                clock=rig.clock,
                before_run=None if home or options.yes else _ask_to_place,
                on_message=also_told(say, link),
            )
            assert bench.plan is not None
            x, y, yaw = bench.plan.home_pose_map
            say(f"start at ({x:.2f}, {y:.2f}) m, heading {yaw:.2f} rad (--start-yaw); procedures:")
            for line in bench.plan.summary():
                say(f"  {line}")
            question = (
                "run the calibration campaign on the robot now? (Ctrl-C, space, q or Esc stops it)"
            )
            if not confirm_first_motion(question, options.yes):
                yield None
                return

            def ran() -> None:
                driver.close()
                writing.append(True)

            yield _Bench(bench, start, None, ran, driver)
        except BaseException:
            driver.close()  # a zero command first, whatever happened
            if bench is not None and bench.recordings and not writing:
                _keep_recordings(bench.recordings, out)
            raise


def _ask_to_place(name: str) -> None:
    """Without homing: the user brings the robot back to its start before each run."""
    from omnical.errors import LimitError

    if not typer.confirm(f"{name}: robot back at its start, facing --start-yaw? run it now?"):
        msg = f"stopped before {name}: the robot was not placed"
        raise LimitError(msg)


def _keep_recordings(recordings: Mapping[str, Recording], out: Path) -> None:
    """Write the runs made before an interruption or an error to OUT.partial/recordings/
    (OUT itself, an earlier campaign perhaps, stays as it was)."""
    from omnical.bags.bag import write_bag
    from omnical.errors import OmnicalError
    from omnical.reports.outputs import claim_directory

    try:
        kept = claim_directory(out, overwrite=True, writer="omnical calibrate campaign")
        with kept.staged(keep=True) as staging:
            for name, recording in recordings.items():
                write_bag(recording, staging / "recordings" / f"{name}.mcap")
    except OmnicalError as err:  # the error or interruption being raised says the rest
        typer.echo(f"omnical: robot stopped; the runs could not be kept: {err}", err=True)
        return
    typer.echo(
        f"omnical: robot stopped; kept {len(recordings)} run{'s' * (len(recordings) != 1)} "
        f"in {kept.kept_at}/recordings "
        "(omnical calibrate estimate can analyse them)",
        err=True,
    )


def _write_campaign(
    result: CampaignResult,
    out: Path,
    robot: RobotDescription,
    beacons: BeaconMap | None,
    on_line: Callable[[str], None],
    *,
    figures: bool = True,
    overwrite: bool = False,
) -> list[str]:
    """Write OUT whole (a stop meanwhile keeps it as OUT.partial); one ``wrote ...`` line per
    file or group of files."""
    from omnical.cli.output import tell
    from omnical.reports.campaign import write_campaign

    files = write_campaign(
        result,
        out,
        robot,
        beacons=beacons,
        figures=figures,
        on_progress=on_line,
        overwrite=overwrite,  # checked before the run, again when it is swapped in
        notify=tell,
    )
    written = [
        f"wrote {files.files[role]}" for role in ("factors", "header", "ros_params", "report")
    ]
    n_figures, n_bags = len(files.by_kind("figure")), len(files.by_kind("recording"))
    written.append(
        f"wrote {n_figures} figures in {out / 'figures'}, {n_bags} recordings in {out / 'recordings'}"
    )
    return written

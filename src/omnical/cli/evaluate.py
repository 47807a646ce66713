"""``omnical evaluate``: the errors of a recording's estimates against a reference.

Reference ``/ground_truth`` unless ``--reference``, ``--reference-file`` or ``--reference-topic``;
odometry ``/odom`` unless ``--wheel-topic`` or ``--odometry``; OUT is written whole.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import AlignMode, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import Align, Overwrite, Robot
from omnical.cli.output import console, say
from omnical.cli.reference_options import (
    DeadWheelTopic,
    FactorsFile,
    Odometry,
    Reference,
    ReferenceChild,
    ReferenceFile,
    ReferenceTopic,
    Sources,
    WheelTopic,
)

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence
    from typing import Any

    from numpy.typing import NDArray

    from omnical.estimation.handover import Handover
    from omnical.evaluation.association import Trajectory
    from omnical.evaluation.metrics import Tracked
    from omnical.ips.solve.fixes import Fixes
    from omnical.recording.recording import Recording, Table
    from omnical.robot.description import DeadWheel

__all__ = ["evaluate"]


def evaluate(
    run: Annotated[Path, typer.Argument(metavar="BAG", help="Recording to evaluate.")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output directory (metrics.json, figures).")
    ],
    reference: Reference = "ground_truth",
    reference_topic: ReferenceTopic = None,
    reference_child: ReferenceChild = None,
    reference_file: ReferenceFile = None,
    wheel_topic: WheelTopic = None,
    odometry: Odometry = None,
    # recording.topics.DEAD_WHEELS written out: the CLI imports no library at start-up
    dead_wheel_topic: DeadWheelTopic = "/dead_wheels",
    align: Align = AlignMode.SE2.value,
    robot: Robot = "rosy-mecanum",
    factors: FactorsFile = None,
    no_figures: Annotated[
        bool,
        typer.Option("--no-figures", help="Draw no figures (most of the time of a short run)."),
    ] = False,
    overwrite: Overwrite = False,
) -> None:
    """RMSE (Euclidean, x, y), max and final error against the reference of odometry, vendor
    IPS, multilateration and the smoothed trajectory.

    Multilateration counts trusted fixes only. The smoothed trajectory fuses the odometry, the
    trusted fixes and the gyro (when recorded) in a batch smoother with the hedgehog's lever
    arm (estimated when the run turns) and the IPS latency (estimated); it checks itself
    against its fixes and, when the check passes, is the estimate to quote without ground
    truth. Prints a table and the check, writes OUT/metrics.json, OUT/report.md and figures
    (paths, x(t) and y(t), speeds; not with --no-figures). Exit status 3 (after writing) when a built-in --reference
    is not the path the recording drove.
    """
    with handled_errors():
        from omnical.cli.output import tell
        from omnical.reports.outputs import claim_directory

        mode = parse_choice(AlignMode, align, "--align")
        given = None if reference == "ground_truth" else reference
        inputs = Sources.of(
            odometry, wheel_topic, dead_wheel_topic, reference_topic, reference_child,
            reference_file, given, factors=factors,
        )  # fmt: skip
        claimed = claim_directory(out, overwrite=overwrite, writer="omnical evaluate", notify=tell)
        with claimed.staged(tell) as staging:
            drawn, off_path = _evaluate(
                run, staging, reference, mode, robot, inputs, not no_figures
            )
        say(f"wrote {out / 'metrics.json'}, {out / 'report.md'} and {drawn} figures in {out}")
    if off_path is not None:
        from omnical.cli.errors import EXIT_NO_RESULT

        typer.echo(f"omnical: {off_path}", err=True)
        raise typer.Exit(EXIT_NO_RESULT)


def _corrected(recording: Recording, inputs: Sources, name: str) -> Recording:
    """The recording with its odometry corrected by ``--factors`` (if given)."""
    if inputs.factors is None:
        return recording
    from omnical.calibration.campaign import installed_from_recordings
    from omnical.calibration.factors_io import read_factors
    from omnical.estimation.odometry_sources import corrected_odometry

    factors = read_factors(inputs.factors).factors
    installed = None
    if inputs.odometry == "odom":  # the vehicle controller's: undo what it compensated
        installed = installed_from_recordings([recording])
    say(f"{name}: odometry corrected with {inputs.factors}")
    return corrected_odometry(recording, factors, installed)


def _reference(
    run: Path, recording: Recording, reference: str, inputs: Sources
) -> Trajectory | None:
    """The reference the options name; None: the recording's /ground_truth."""
    from omnical.cli.reference_options import reference_for, reference_from_spec
    from omnical.errors import RecordingError
    from omnical.recording.topics import GROUND_TRUTH

    external = reference_for(
        run, recording, inputs.reference_topic, inputs.reference_child, inputs.reference_file
    )
    if external is not None:
        return external
    if reference != "ground_truth":
        return reference_from_spec(run.name, recording, reference)
    if not recording.has(GROUND_TRUTH):
        from omnical.bags.reference_topics import bag_topics, pose_topics

        poses = pose_topics(bag_topics(run))
        topic = (
            f"--reference-topic {poses[0]} (its pose topic"
            + (f"s: {', '.join(poses)})" if len(poses) > 1 else ")")
            if poses
            else "--reference-topic TOPIC (motion capture in the bag)"
        )
        msg = (
            f"{run.name} has no /ground_truth; give the reference: {topic}, "
            "--reference-file REF.tum|REF.csv, or --reference NAME"
        )
        raise RecordingError(msg)
    return None


def _reference_label(reference: str, inputs: Sources) -> str:
    """The reference's name for the table's title."""
    if inputs.reference_topic is not None:
        child = f" → {inputs.reference_child}" if inputs.reference_child else ""
        return inputs.reference_topic + child
    if inputs.reference_file is not None:
        return inputs.reference_file.name
    from omnical.recording.topics import GROUND_TRUTH

    return GROUND_TRUTH if reference == "ground_truth" else Path(reference).name


def _reference_is(topic: str, reference: str, inputs: Sources) -> bool:
    """Whether the reference is the recording's ``topic`` (given by name or the default)."""
    from omnical.cli.reference_options import same_topic
    from omnical.recording.topics import GROUND_TRUTH

    if inputs.reference_topic is not None:
        return same_topic(inputs.reference_topic, topic)
    return inputs.reference_file is None and reference == "ground_truth" and topic == GROUND_TRUTH


def _hint_wheel_topic(run: Path, warn: Callable[[str], None], *, nothing_else: bool) -> None:
    """A bag without /odom: with wheel encoders, say which option computes the odometry; with
    nothing else to evaluate either (no positioning topics), refuse, naming the bag's topics.

    Raises:
        ConfigError: nothing to evaluate.
    """
    from omnical.bags.reference_topics import bag_topics
    from omnical.errors import ConfigError

    kinds = bag_topics(run)
    joints = [t for t, kind in kinds.items() if kind.endswith("JointState")]
    hint = (
        f"the bag has wheel encoders ({', '.join(joints)}): --wheel-topic {joints[0]} computes "
        "the odometry from them"
        if joints
        else f"its topics: {', '.join(sorted(kinds)) or 'none'}"
    )
    if nothing_else:
        msg = f"{run}: nothing to evaluate: no /odom and no positioning topics; {hint}"
        raise ConfigError(msg)
    if joints:
        warn(f"{run}: no /odom; {hint}")


def _evaluate(
    run: Path,
    out: Path,
    reference: str,
    align: AlignMode,
    robot: str,
    inputs: Sources,
    figures: bool = True,
) -> tuple[int, str | None]:
    """Evaluate ``run``, print the table, write the files in ``out`` (the figures if
    ``figures``); the number of figures and, for a built-in reference the recording does not
    follow, why (:func:`_off_path`)."""
    from rich.markup import escape
    from rich.table import Table

    from omnical.bags.bag import read_bag
    from omnical.cli.reference_options import odometry_for, warn
    from omnical.cli.robot_target import load_said_robot
    from omnical.recording.topics import (
        BEACON_RAW_DISTANCE,
        EVALUATED,
        EVENTS,
        GROUND_TRUTH,
        HEDGE_POS_ANG,
        IMU,
        IMU_MAG,
        ODOM,
    )

    description = load_said_robot(robot)
    topics: tuple[str, ...] = EVALUATED
    if description.dead_wheels:  # seed 003's estimate: dead-wheel encoders and magnetometer
        topics = (*topics, inputs.dead_wheel_topic, IMU_MAG)
    if inputs.wheel_topic is not None:
        topics = (*topics, inputs.wheel_topic)
    if inputs.factors is not None:  # the installed factors, to undo them
        topics = (*topics, EVENTS)
    slim = (
        inputs.odometry == "odom"
        and inputs.factors is None
        and inputs.wheel_topic is None
        and not description.dead_wheels
        and _bag_bytes(run) >= _STREAM_FROM_BYTES
    )
    located: Handover[Fixes] | None = None
    if slim:
        recording, located = _read_located(run, topics)
    else:
        recording = read_bag(run, topics)
    for note in recording.notes:
        warn(note)
    if inputs.odometry != "odom":  # else /odom as it is (or none: the other estimates)
        recording = odometry_for(
            recording,
            inputs.odometry,
            description,
            wheel_topic=inputs.wheel_topic,
            dead_wheel_topic=inputs.dead_wheel_topic,
            name=run.name,
        )
    recording = _corrected(recording, inputs, run.name)
    if inputs.odometry == "odom" and _reference_is(ODOM, reference, inputs):
        warn(
            f"the reference {inputs.reference_topic} is the odometry evaluated ({ODOM}): its "
            "errors are zero by construction; give an independent reference (motion capture)"
        )
    ref = _reference(run, recording, reference, inputs)
    if inputs.odometry == "odom" and not recording.has(ODOM):
        located_anything = slim or any(
            recording.has(t) for t in (HEDGE_POS_ANG, BEACON_RAW_DISTANCE)
        )
        _hint_wheel_topic(run, warn, nothing_else=not located_anything)
    with_gyro = recording.has(IMU)
    long_run = recording.has(ODOM) and recording.duration_s > _LEAN_FROM_S
    box = [recording]  # handed over: the tables the figures do not draw are let go before them
    del recording
    results, drawn = _evaluate_and_write(
        box,
        run.name,
        out,
        ref,
        align,
        description.hedge_offset_m,
        description.dead_wheels,
        drop_ground_truth=_reference_is(GROUND_TRUTH, reference, inputs),
        lean=slim or long_run,
        fixes=located,
        reread=(lambda names: _read_slim(run, names)) if slim else None,
        figures=figures,
    )
    label = _reference_label(reference, inputs)
    table = Table(
        title=escape(f"{run.name}: errors (m) against the reference ({label}), alignment {align}")
    )
    for col in ("estimate", "RMSE", "RMSE x", "RMSE y", "max", "final", "own 1σ"):
        table.add_column(col, justify="left" if col == "estimate" else "right")
    for name, t in results.items():
        m = t.metrics
        values = (m.rmse_m, m.rmse_x_m, m.rmse_y_m, m.max_m, m.final_m)
        sigma = t.sigma_rms_m
        own = "" if sigma is None or name != "smoothed" else f"{sigma:.4f}"
        table.add_row(name, *(f"{v:.4f}" for v in values), own)
    console().print(table)
    smoothed = results.get("smoothed")
    if smoothed is not None and smoothed.smoothing is not None:
        _say_smoothed(smoothed, with_gyro)
    builtin = inputs.reference_topic is None and inputs.reference_file is None
    return drawn, _off_path(reference, align, results) if builtin else None


def _off_path(reference: str, align: AlignMode, results: Mapping[str, Tracked]) -> str | None:
    """Why ``results`` say the recording does not follow the built-in ``reference``, or None
    (:func:`~omnical.evaluation.reference_input.off_builtin_path`)."""
    from omnical.evaluation.reference_input import off_builtin_path

    rmse_m = {name: t.metrics.rmse_m for name, t in results.items()}
    return off_builtin_path(reference, align.value, rmse_m)


def _say_smoothed(smoothed: Tracked, with_gyro: bool) -> None:
    """What ``evaluate`` prints of the smoothed track: its RMSE, own 1σ and self-check, and a
    warning when it is not the estimate to quote."""
    from omnical.cli.reference_options import warn

    sm = smoothed.smoothing
    if sm is None:  # pragma: no cover - the caller checks
        return
    arm = sm.hedge_offset_m
    say(
        f"smoothed (odometry + trusted fixes{' + gyro' if with_gyro else ''}): "
        f"RMSE {smoothed.metrics.rmse_m:.4f} m, its own 1σ {smoothed.sigma_rms_m or 0.0:.4f} m; "
        f"IPS latency {sm.latency_s * 1e3:.0f} ± {sm.latency_sigma_s * 1e3:.0f} ms; "
        f"lever arm ({arm[0]:+.3f}, {arm[1]:+.3f}) m"
        + (" (estimated)" if sm.shared_dict()["hedge_offset_x_m"][1] > 0.0 else " (given)")
    )
    check = sm.check
    if check is not None:
        say(
            f"smoothed self-check: fix residuals χ²/dof {check.fix_chi2_per_dof:.2f}, "
            f"{100 * check.fixes_in_band_95:.1f} % of the trusted fixes inside its 95 % band, "
            f"odometry noise ×{check.odometry_noise_scale:.2f} of the model: "
            + ("passed" if check.passed else "FAILED")
        )
    if check is not None and not check.passed:
        warn(
            "the smoothed track fails its self-check ("
            + "; ".join(check.reasons)
            + "): neither it nor its own 1σ is the estimate to quote; quote multilateration"
        )
    elif not sm.converged:
        warn(
            f"the smoother did not converge in {sm.iterations} iterations: the smoothed "
            "estimate is not one to quote (too few fixes, or long stretches without them)"
        )


_LEAN_FROM_S = 300.0
"""A run longer than this (the smoother's keyframe threshold, ``SmootherParams.long_run_s``)
is evaluated lean (:func:`_evaluate_and_write`): the same measures, figures drawn from the
samples they show."""

_STREAM_FROM_BYTES = 20_000_000
"""Bags this large (≈ 15 minutes of a twin run) are read part by part with only the columns
used (:func:`_read_slim`); a smaller one whole (the streaming reader's own few megabytes
would outweigh what it saves)."""


def _bag_bytes(run: Path) -> int:
    """The size of the bag's files on disk (0 when there is no such bag: read_bag says so)."""
    from omnical.bags.bag import resolve_source
    from omnical.errors import RecordingError

    try:
        source = resolve_source(run)
    except RecordingError:
        return 0
    files = [source] if source.is_file() else [p for p in source.iterdir() if p.is_file()]
    return sum(p.stat().st_size for p in files)


def _slim_columns() -> dict[str, tuple[str, ...]]:
    """The columns the default evaluation reads of these topics (the smoother's gyro; the truth's
    pose; the vendor's fixes and, for locate, their height): the others (a third of a long
    recording's decoded tables) are not kept."""
    from omnical.recording.topics import GROUND_TRUTH, HEDGE_POS_ANG, IMU

    return {
        IMU: ("gyro_z_radps",),
        GROUND_TRUTH: ("x_m", "y_m", "yaw_rad"),
        HEDGE_POS_ANG: ("address", "x_m", "y_m", "z_m", "flags"),
    }


def _read_slim(run: Path, topics: Sequence[str]) -> Recording:
    """``read_bag(run, topics)`` with only :func:`_slim_columns` of their topics, part by part."""
    from omnical.bags.stream import read_selected

    return read_selected(run, topics, _slim_columns())


def _read_located(run: Path, topics: Sequence[str]) -> tuple[Recording, Handover[Fixes] | None]:
    """:func:`_read_slim` of ``topics`` and omnical's multilateration of the run (handed over,
    None without raw distances), the multilateration first: what it reads (the raw distances,
    the beacons, the hedgehog's height from the vendor's fixes) read and located alone, the raw
    distances and the beacons let go, then the other topics read — so the located fixes, not the
    other tables, are held while it works. The same tables, start and notes as one read (the
    notes in the topics' order: these come last)."""
    from omnical.estimation.handover import Handover as _Handover
    from omnical.evaluation.metrics import let_go
    from omnical.ips.from_recording import locate
    from omnical.recording.recording import Recording as _Recording
    from omnical.recording.topics import BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG

    located_reads = (HEDGE_POS_ANG, BEACON_RAW_DISTANCE, BEACONS_POS_A)
    first = [n for n in topics if n in located_reads]
    if BEACON_RAW_DISTANCE not in first:
        return _read_slim(run, topics), None
    part = _read_slim(run, first)
    located = None
    if part.has(BEACON_RAW_DISTANCE):  # as track_recording would locate it
        located = _Handover(locate(part)[0])
    part = let_go(part, BEACON_RAW_DISTANCE, BEACONS_POS_A)
    rest = _read_slim(run, [n for n in topics if n not in located_reads])
    recording = _Recording(
        {**rest.tables, **part.tables},
        {**rest.skipped_topics, **part.skipped_topics},
        (*rest.notes, *part.notes),
    )
    return recording, located


def _for_figures(recording: Recording, *, lean: bool = False) -> Recording:
    """What the figures read of the recording (``/cmd_vel`` and ``/odom``, the speeds), with
    its start (the first row of the topic that starts it): on a long run, the other tables
    (the truth, the IMU, the raw distances) are as large as these two.

    ``lean`` (a long run): only the speeds' columns, at the rows the figures draw
    (:func:`~omnical.evaluation.metrics.figure_rows` of the speed and the yaw rate, and every
    change of the commands when there are not too many).
    """
    from omnical.recording.recording import Recording as _Recording
    from omnical.recording.topics import CMD_VEL, ODOM

    start = recording.start_ns
    kept: dict[str, Table] = {
        n: recording.topic(n) for n in (CMD_VEL, ODOM) if n in recording.topics
    }
    if lean:
        kept = {n: _speed_rows(table) for n, table in kept.items()}
    if not any(len(t) and int(t.t_ns[0]) == start for t in kept.values()):
        first = next(
            n for n in recording.topics if recording.has(n) and recording.topic(n).t_ns[0] == start
        )
        kept[first] = recording.topic(first).take([0])
    return _Recording(kept, recording.skipped_topics, recording.notes)


_SPEEDS = ("vx_mps", "vy_mps", "wz_radps")


def _speed_rows(table: Table) -> Table:
    """The speeds of a twist table (``/cmd_vel``, ``/odom``) at the rows a figure draws."""
    import numpy as np

    from omnical.evaluation import metrics
    from omnical.recording.recording import Table as _Table

    names = [n for n in _SPEEDS if n in table.names]
    if len(names) < len(_SPEEDS) or len(table) <= metrics.FIGURE_ROWS:
        return _Table(table.t_ns, {n: table[n] for n in names})
    vx, vy, wz = (table[n] for n in _SPEEDS)
    rows = metrics.figure_rows((np.hypot(vx, vy), wz))
    changed = np.flatnonzero((vx[1:] != vx[:-1]) | (vy[1:] != vy[:-1]) | (wz[1:] != wz[:-1]))
    if changed.size <= metrics.FIGURE_ROWS:  # a command's steps, exactly
        rows = np.union1d(rows, np.concatenate([changed, changed + 1]))
    return _Table(table.t_ns[rows], {n: table[n][rows] for n in names})


def _for_tracking(recording: Recording) -> Recording:
    """A long run's recording without what only the figures read (``/cmd_vel``, the speeds of
    ``/odom``: :func:`_for_figures` has them), its start kept."""
    from omnical.evaluation.metrics import let_go
    from omnical.recording.recording import Table as _Table
    from omnical.recording.topics import CMD_VEL, ODOM

    if recording.has(ODOM):
        od = recording.topic(ODOM)
        pose: dict[str, NDArray[Any]] = {
            n: od[n] for n in ("x_m", "y_m", "yaw_rad") if n in od.names
        }
        recording = recording.with_table(ODOM, _Table(od.t_ns, pose))
    return let_go(recording, CMD_VEL)


def _evaluate_and_write(
    box: list[Recording],
    name: str,
    out: Path,
    reference: Trajectory | str | None,
    align: AlignMode,
    hedge_offset_m: tuple[float, float, float] | None = None,
    dead_wheels: Sequence[DeadWheel] = (),
    *,
    drop_ground_truth: bool = False,
    lean: bool = False,
    fixes: Handover[Fixes] | None = None,
    reread: Callable[[tuple[str, ...]], Recording] | None = None,
    figures: bool = True,
) -> tuple[Mapping[str, Tracked], int]:
    """The calls of ``omnical evaluate`` into :mod:`omnical.evaluation` and :mod:`omnical.reports`.

    ``box`` holds the recording, handed over: it is emptied, and once the estimates are
    evaluated only what the figures read of it is kept (:func:`_for_figures`). ``reference``:
    a trajectory, a name or path for :func:`load_reference`, or None (or ``ground_truth``) for
    the recording's ``/ground_truth``. ``drop_ground_truth``: the ground
    truth is the reference, so its (zero) errors are left out (unless nothing else is there).
    ``lean`` (a long run): what the figures draw is taken first (:func:`_for_figures`), the
    rest handed over to a lean :func:`track_recording` that lets each table go once used and
    keeps of every estimate only what the figures draw (same measures). Writes
    ``out/metrics.json``, the figures (if ``figures``) and ``out/report.md``; returns the evaluation by
    estimate and the number of figures written. ``fixes``: omnical's multilateration of the
    run, handed over (None: located from the recording's raw distances); ``reread``: the
    recording's tables read again from the bag (:func:`track_recording`'s, lean only).
    """
    from functools import partial

    from omnical.evaluation.metrics import Handover, track_recording
    from omnical.evaluation.reference_input import load_reference
    from omnical.reports.tracking import write_evaluation

    recording = box.pop()
    if isinstance(reference, str):
        ref = None if reference == "ground_truth" else load_reference(reference, recording)
    else:
        ref = reference
    evaluate = partial(
        track_recording,
        reference=ref,
        align=align.value,
        hedge_offset_m=hedge_offset_m,
        dead_wheels=dead_wheels,
        ground_truth_alone=drop_ground_truth,
        fixes=fixes,
    )
    del fixes  # in the partial: taken (let go) by the evaluation
    with console().status("evaluating"):
        if lean:  # the speeds the figures draw first; the rest handed over, let go once used
            drawn = _for_figures(recording, lean=True)
            hand = Handover(_for_tracking(recording))
            del recording
            tracked = evaluate(hand, lean=True, reread=reread)
        else:
            tracked = evaluate(recording)
            drawn = _for_figures(recording)
            del recording
    others = {k: t for k, t in tracked.items() if k != "ground_truth"}
    if drop_ground_truth and others:
        tracked = others
    del others
    if lean:
        tracked = _for_report(tracked)
    files = write_evaluation(tracked, drawn, out, name=name, align=align.value, figures=figures)
    return tracked, len(files.figures)


def _for_report(tracked: Mapping[str, Tracked]) -> dict[str, Tracked]:
    """A long run's evaluation (reduced to the rows the figures draw) without what neither the
    figures nor the report read (the headings, the covariances, the smoothed track's poses):
    on a long run, ≈ 5 MB held through the figures. The measures, the own 1σ and what the
    report says of the smoother (:func:`~omnical.evaluation.metrics.smoothing_summary`) are
    kept."""
    from dataclasses import replace

    import numpy as np

    out: dict[str, Tracked] = {}
    for name, t in tracked.items():
        smoothing = t.smoothing
        if smoothing is not None:
            empty = np.zeros((0, 3))
            smoothing = replace(
                smoothing, t_s=np.zeros(0), poses=empty, covariance=empty.reshape(0, 3, 3)
            )
        association = replace(
            t.association,
            estimate_yaw_rad=None,
            reference_yaw_rad=None,
            estimate_covariance_xy_m2=None,
        )
        out[name] = replace(
            t,
            association=association,
            alignment=replace(t.alignment, yaw_rad=None),
            smoothing=smoothing,
            own_sigma_rms_m=t.sigma_rms_m,
        )
    return out

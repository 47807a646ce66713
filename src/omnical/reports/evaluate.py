"""``omnical evaluate``'s work on one recording, for the command and ``fleet evaluate``
(:func:`evaluate_bag`): the topics read, the odometry and reference its options name, the
evaluation and its files; a big bag read part by part and a long run evaluated lean.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
from numpy.typing import NDArray

from omnical.bags.bag import read_bag, resolve_source
from omnical.bags.stream import read_selected
from omnical.choices import AlignMode
from omnical.errors import ConfigError, RecordingError
from omnical.estimation.handover import Handover
from omnical.evaluation import metrics
from omnical.evaluation.metrics import Tracked, let_go, track_recording
from omnical.evaluation.reference_input import load_reference, off_builtin_path
from omnical.ips.from_recording import locate
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import (
    BEACON_RAW_DISTANCE,
    BEACONS_POS_A,
    CMD_VEL,
    EVALUATED,
    EVENTS,
    GROUND_TRUTH,
    HEDGE_POS_ANG,
    IMU,
    IMU_MAG,
    ODOM,
)
from omnical.reports.tracking import write_evaluation
from omnical.services.sources import (
    ReadReference,
    Sources,
    odometry_for,
    reference_for,
    reference_from_spec,
    same_topic,
)
from omnical.services.voice import SILENT, Voice

if TYPE_CHECKING:
    from omnical.evaluation.association import Trajectory
    from omnical.ips.solve.fixes import Fixes
    from omnical.robot.description import DeadWheel, RobotDescription

__all__ = ["Evaluation", "evaluate_bag"]


@dataclass(frozen=True)
class Evaluation:
    """What :func:`evaluate_bag` measured and wrote.

    Attributes:
        tracked: the evaluation by estimate, as written.
        figures: the number of figures written.
        reference: the reference, as read.
        off_path: why the recording does not follow the built-in ``--reference`` it was given
            (:func:`~omnical.evaluation.reference_input.off_builtin_path`); None if it does, or
            for another reference.
        with_gyro: whether the recording has the gyro (the smoothed track fused it).
    """

    tracked: Mapping[str, Tracked]
    figures: int
    reference: ReadReference
    off_path: str | None
    with_gyro: bool


def evaluate_bag(
    bag: Path,
    out: Path,
    *,
    name: str,
    robot: RobotDescription,
    sources: Sources,
    reference: str = "ground_truth",
    align: AlignMode,
    figures: bool = True,
    lean: bool = True,
    hints: bool = True,
    voice: Voice = SILENT,
) -> Evaluation:
    """Evaluate ``bag`` (``name`` in the files' titles) against the reference ``sources`` or
    ``reference`` name (``ground_truth``: the recording's; a built-in path or a file), its
    odometry from ``sources``, and write ``metrics.json``, ``report.md`` and the figures (if
    ``figures``) in ``out``. ``lean``: a big bag (:data:`_STREAM_FROM_BYTES`) read part by
    part and a long run (:data:`_LEAN_FROM_S`) evaluated lean, the same measures (False: whole,
    as the fleet has it). ``hints``: a refusal names what the bag holds (its pose topics, its
    wheel encoders: read again from it), the single command's messages (False: the fleet rows'
    short ones). ``voice``: what was read and used, the warnings, the spinner.

    Raises:
        RecordingError: no /ground_truth and no other reference (and as reading and evaluating
            the recording raise).
        ConfigError: nothing to evaluate (no /odom, no positioning topics).
    """
    topics: tuple[str, ...] = EVALUATED
    if robot.dead_wheels:  # seed 003's estimate: dead-wheel encoders and magnetometer
        topics = (*topics, sources.dead_wheel_topic, IMU_MAG)
    if sources.wheel_topic is not None:
        topics = (*topics, sources.wheel_topic)
    if sources.factors is not None:  # the installed factors, to undo them
        topics = (*topics, EVENTS)
    slim = (
        lean
        and sources.odometry == "odom"
        and sources.factors is None
        and sources.wheel_topic is None
        and not robot.dead_wheels
        and _bag_bytes(bag) >= _STREAM_FROM_BYTES
    )
    located: Handover[Fixes] | None = None
    if slim:
        recording, located = _read_located(bag, topics)
    else:
        recording = read_bag(bag, topics)
    for note in recording.notes:
        voice.warn(note)
    if sources.odometry != "odom":  # else /odom as it is (or none: the other estimates)
        recording = odometry_for(recording, sources, robot, name=bag.name, voice=voice)
    recording = _corrected(recording, sources, bag.name, voice)
    if sources.odometry == "odom" and _reference_is(ODOM, reference, sources):
        voice.warn(
            f"the reference {sources.reference_topic} is the odometry evaluated ({ODOM}): its "
            "errors are zero by construction; give an independent reference (motion capture)"
        )
    used = _reference(bag, recording, reference, sources, hints, voice)
    if sources.odometry == "odom" and not recording.has(ODOM):
        located_anything = slim or any(
            recording.has(t) for t in (HEDGE_POS_ANG, BEACON_RAW_DISTANCE)
        )
        if hints:
            _hint_wheel_topic(bag, voice.warn, nothing_else=not located_anything)
        elif not located_anything:
            msg = f"{bag.name}: nothing to evaluate: no /odom and no positioning topics"
            raise ConfigError(msg)
    with_gyro = recording.has(IMU)
    run_s = recording.duration_s
    long_run = lean and recording.has(ODOM) and run_s > _LEAN_FROM_S
    box = [recording]  # handed over: the tables the figures do not draw are let go before them
    del recording
    tracked, drawn = _evaluate_and_write(
        box,
        name,
        out,
        used.trajectory,
        align,
        robot.hedge_offset_m,
        robot.dead_wheels,
        drop_ground_truth=_reference_is(GROUND_TRUTH, reference, sources),
        lean=slim or long_run,
        fixes=located,
        reread=(lambda names: _read_slim(bag, names)) if slim else None,
        figures=figures,
        voice=voice,
    )
    short = _short_reference(tracked, run_s)  # a short reference, or short estimates
    if short:
        voice.warn(short)
    off_path = None
    if sources.reference_topic is None and sources.reference_file is None:  # --reference's
        rmse_m = {key: t.metrics.rmse_m for key, t in tracked.items()}
        off_path = off_builtin_path(reference, align.value, rmse_m)
    return Evaluation(tracked, drawn, used, off_path, with_gyro)


def _corrected(recording: Recording, sources: Sources, name: str, voice: Voice) -> Recording:
    """The recording with its odometry corrected by ``--factors`` (if given)."""
    if sources.factors is None:
        return recording
    from omnical.calibration.campaign import installed_from_recordings
    from omnical.calibration.factors_io import read_factors
    from omnical.estimation.odometry_sources import corrected_odometry

    factors = read_factors(sources.factors).factors
    installed = None
    if sources.odometry == "odom":  # the vehicle controller's: undo what it compensated
        installed = installed_from_recordings([recording])
    voice.say(f"{name}: odometry corrected with {sources.factors}")
    return corrected_odometry(recording, factors, installed)


def _reference(
    bag: Path, recording: Recording, reference: str, sources: Sources, hints: bool, voice: Voice
) -> ReadReference:
    """The reference the options name, read (its trajectory None: the recording's
    /ground_truth).

    Raises:
        RecordingError: none named, and the recording has no /ground_truth.
    """
    external = reference_for(bag, recording, sources, voice)
    if external is not None:
        return external
    if reference != "ground_truth":
        return reference_from_spec(bag.name, recording, reference, voice)
    if recording.has(GROUND_TRUTH):
        return ReadReference(None, GROUND_TRUTH)
    if not hints:
        msg = (
            f"{bag.name} has no /ground_truth; give the reference: "
            "--reference-topic, --reference-file or --reference"
        )
        raise RecordingError(msg)
    from omnical.bags.reference_topics import bag_topics, pose_topics

    poses = pose_topics(bag_topics(bag))
    topic = (
        f"--reference-topic {poses[0]} (its pose topic"
        + (f"s: {', '.join(poses)})" if len(poses) > 1 else ")")
        if poses
        else "--reference-topic TOPIC (motion capture in the bag)"
    )
    msg = (
        f"{bag.name} has no /ground_truth; give the reference: {topic}, "
        "--reference-file REF.tum|REF.csv, or --reference NAME"
    )
    raise RecordingError(msg)


def _reference_is(topic: str, reference: str, sources: Sources) -> bool:
    """Whether the reference is the recording's ``topic`` (given by name or the default)."""
    if sources.reference_topic is not None:
        return same_topic(sources.reference_topic, topic)
    return sources.reference_file is None and reference == "ground_truth" and topic == GROUND_TRUTH


def _hint_wheel_topic(run: Path, warn: Callable[[str], None], *, nothing_else: bool) -> None:
    """A bag without /odom: with wheel encoders, say which option computes the odometry; with
    nothing else to evaluate either (no positioning topics), refuse, naming the bag's topics.

    Raises:
        ConfigError: nothing to evaluate.
    """
    from omnical.bags.reference_topics import bag_topics

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
    return {
        IMU: ("gyro_z_radps",),
        GROUND_TRUTH: ("x_m", "y_m", "yaw_rad"),
        HEDGE_POS_ANG: ("address", "x_m", "y_m", "z_m", "flags"),
    }


def _read_slim(run: Path, topics: Sequence[str]) -> Recording:
    """``read_bag(run, topics)`` with only :func:`_slim_columns` of their topics, part by part."""
    return read_selected(run, topics, _slim_columns())


def _read_located(run: Path, topics: Sequence[str]) -> tuple[Recording, Handover[Fixes] | None]:
    """:func:`_read_slim` of ``topics`` and omnical's multilateration of the run (handed over,
    None without raw distances), the multilateration first: what it reads (the raw distances,
    the beacons, the hedgehog's height from the vendor's fixes) read and located alone, the raw
    distances and the beacons let go, then the other topics read — so the located fixes, not the
    other tables, are held while it works. The same tables, start and notes as one read (the
    notes in the topics' order: these come last)."""
    located_reads = (HEDGE_POS_ANG, BEACON_RAW_DISTANCE, BEACONS_POS_A)
    first = [n for n in topics if n in located_reads]
    if BEACON_RAW_DISTANCE not in first:
        return _read_slim(run, topics), None
    part = _read_slim(run, first)
    located = None
    if part.has(BEACON_RAW_DISTANCE):  # as track_recording would locate it
        located = Handover(locate(part)[0])
    part = let_go(part, BEACON_RAW_DISTANCE, BEACONS_POS_A)
    rest = _read_slim(run, [n for n in topics if n not in located_reads])
    recording = Recording(
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
    return Recording(kept, recording.skipped_topics, recording.notes)


_SPEEDS = ("vx_mps", "vy_mps", "wz_radps")


def _speed_rows(table: Table) -> Table:
    """The speeds of a twist table (``/cmd_vel``, ``/odom``) at the rows a figure draws."""
    names = [n for n in _SPEEDS if n in table.names]
    if len(names) < len(_SPEEDS) or len(table) <= metrics.FIGURE_ROWS:
        return Table(table.t_ns, {n: table[n] for n in names})
    vx, vy, wz = (table[n] for n in _SPEEDS)
    rows = metrics.figure_rows((np.hypot(vx, vy), wz))
    changed = np.flatnonzero((vx[1:] != vx[:-1]) | (vy[1:] != vy[:-1]) | (wz[1:] != wz[:-1]))
    if changed.size <= metrics.FIGURE_ROWS:  # a command's steps, exactly
        rows = np.union1d(rows, np.concatenate([changed, changed + 1]))
    return Table(table.t_ns[rows], {n: table[n][rows] for n in names})


def _for_tracking(recording: Recording) -> Recording:
    """A long run's recording without what only the figures read (``/cmd_vel``, the speeds of
    ``/odom``: :func:`_for_figures` has them), its start kept."""
    if recording.has(ODOM):
        od = recording.topic(ODOM)
        pose: dict[str, NDArray[Any]] = {
            n: od[n] for n in ("x_m", "y_m", "yaw_rad") if n in od.names
        }
        recording = recording.with_table(ODOM, Table(od.t_ns, pose))
    return let_go(recording, CMD_VEL)


_COVERED_AT_LEAST: Final = 0.5
"""Below this share of the run paired with the reference, evaluate warns: the measures speak
for the paired part only."""


def _short_reference(tracked: Mapping[str, Tracked], run_s: float) -> str:
    """A warning when the samples paired with the reference span less than
    :data:`_COVERED_AT_LEAST` of the run for every estimate (a short reference, or short
    estimates), else ""."""
    spans = {  # metrics.n: every paired sample (a long run's association is thinned)
        name: (float(t.association.t_s[-1] - t.association.t_s[0]), t.metrics.n)
        for name, t in tracked.items()
        if len(t.association)
    }
    if not spans or not run_s > 0.0:
        return ""
    name, (span_s, n) = max(spans.items(), key=lambda item: item[1][0])
    if span_s >= _COVERED_AT_LEAST * run_s:
        return ""
    return (
        f"only {span_s:.3g} s of the run's {run_s:.3g} s pair with the reference ({n} samples "
        f"of {name}): the measures speak for that part only"
    )


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
    voice: Voice = SILENT,
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
    recording's tables read again from the bag (:func:`track_recording`'s, lean only);
    ``voice``: the spinner while evaluating.
    """
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
    with voice.status("evaluating"):
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

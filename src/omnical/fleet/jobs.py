"""Fleet jobs: one recording through what ``omnical locate``, ``evaluate`` or ``calibrate
estimate`` call, its files in its own directory, its figures as one row (an error is a row).
Pure and picklable: a job carries paths and options, never data.
"""

from __future__ import annotations

import hashlib
import math
import os
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from contextlib import suppress
from dataclasses import dataclass
from functools import cache, partial
from pathlib import Path
from typing import TYPE_CHECKING, Final

from omnical.fleet.runner import run_chunk
from omnical.fleet.table import INDEX, REASON, STATUS, failure
from omnical.recording.topics import DEAD_WHEELS

if TYPE_CHECKING:
    from omnical.robot.description import RobotDescription
    from omnical.services.sources import Sources

__all__ = [
    "FLEET_COMMANDS",
    "IPS_REFERENCE",
    "REFERENCE",
    "REFERENCE_TIMES",
    "FleetJob",
    "FleetOptions",
    "check_files",
    "check_robot_options",
    "error_row",
    "fleet_header",
    "fleet_job_name",
    "for_recording",
    "reference_label",
    "run_fleet_chunk",
    "run_fleet_job",
]

FLEET_COMMANDS: Final = ("locate", "evaluate", "calibrate")
"""The single commands a fleet runs."""

_NAME: Final = "name"
_RECORDING: Final = "recording"

_LOCATE_COLUMNS: Final = (
    "fixes",
    "ok",
    "degraded",
    "rejected",
    "degenerate",
    "usable_fraction",
    "residual_median_m",
    "fix_sigma_median_m",
    "range_sigma_max_m",
)
REFERENCE: Final = "reference"
"""Column of ``evaluate`` and ``calibrate``: the reference each recording was measured against
(``/ground_truth``, the IPS, a topic, or the file or built-in path, ``{stem}`` replaced)."""

REFERENCE_TIMES: Final = "reference_times"
"""Column: the rule a reference file's times were read by (what the single commands print)."""

IPS_REFERENCE: Final = "the IPS (/beacon_raw_distance)"
"""``calibrate``'s reference without ``--reference-topic`` or ``--reference-file``."""

_ESTIMATES: Final = ("odometry", "ips", "multilateration", "smoothed")
_EVALUATE_COLUMNS: Final = (
    REFERENCE,
    REFERENCE_TIMES,
    *(f"{e}_{m}" for e in _ESTIMATES for m in ("rmse_m", "max_m", "final_m")),
    "smoothed_sigma_m",
)


def _factor_fields() -> tuple[str, ...]:
    from omnical.kinematics.factors import FACTORS

    return tuple(f.field for f in FACTORS)


def fleet_header(command: str) -> list[str]:
    """The columns of ``DIR/fleet.csv`` for ``command``: index, name, recording, status, reason,
    then the command's figures (each factor followed by its 1σ for ``calibrate``)."""
    figures: tuple[str, ...]
    if command == "locate":
        figures = _LOCATE_COLUMNS
    elif command == "evaluate":
        figures = _EVALUATE_COLUMNS
    else:
        figures = (
            "method",
            *(c for f in _factor_fields() for c in (f, f"{f}_sigma")),
            "held",
            REFERENCE,
            REFERENCE_TIMES,
        )
    return [INDEX, _NAME, _RECORDING, STATUS, REASON, *figures]


@dataclass(frozen=True)
class FleetOptions:
    """The single command's options, the same for every recording of the fleet.

    Paths are absolute (workers may run in another directory). A reference file or
    ``reference`` path may hold ``{stem}`` (the recording's name without ``.mcap``/``.bag``)
    and ``{parent}`` (its directory): each recording's own reference (:func:`for_recording`).

    Attributes:
        command: ``locate``, ``evaluate`` or ``calibrate``.
        robot: robot preset or YAML path.
        method: locate's (robust, lsq, grid) or calibrate's (procedures, joint; "" chooses as
            ``calibrate estimate`` does).
        beacons: beacon map YAML ("" for the recording's).
        hedge_z_m: locate's ``--hedge-z`` (None: as locate finds it).
        sigma_m: locate's ``--sigma-m`` (None: learned).
        self_calibrate: locate without ``--no-self-calibration``.
        plot: locate's ``--plot``: ``fixes.png`` beside each ``fixes.csv``.
        allow_poor: locate's ``--allow-poor``: a row even when fewer than half the fixes are
            usable (else an error row, where ``omnical locate`` exits with its own status).
        installed: calibrate's ``--installed`` factors.yaml ("" for none).
        align: evaluate's ``--align``.
        reference: evaluate's ``--reference`` (``ground_truth``, a built-in path, a file).
        reference_topic: ``--reference-topic`` ("" for none).
        reference_child: ``--reference-child`` ("" for none).
        reference_file: ``--reference-file`` ("" for none).
        reference_sigma_m: calibrate's ``--reference-sigma``.
        odometry: ``--odometry`` as resolved (odom, wheels, seed003).
        wheel_topic: ``--wheel-topic`` ("" for none).
        dead_wheel_topic: ``--dead-wheel-topic``.
        factors: evaluate's ``--factors`` ("" for none).
    """

    command: str
    robot: str = "rosy-mecanum"
    method: str = ""
    beacons: str = ""
    hedge_z_m: float | None = None
    sigma_m: float | None = None
    self_calibrate: bool = True
    plot: bool = False
    allow_poor: bool = False
    installed: str = ""
    align: str = "se2"
    reference: str = "ground_truth"
    reference_topic: str = ""
    reference_child: str = ""
    reference_file: str = ""
    reference_sigma_m: float = 0.002
    odometry: str = "odom"
    wheel_topic: str = ""
    dead_wheel_topic: str = DEAD_WHEELS
    factors: str = ""

    def sources(self, recording: str) -> Sources:
        """The odometry and reference options (checked when the fleet started), the files
        ``recording``'s own (:func:`for_recording`)."""
        from omnical.choices import OdometrySource
        from omnical.services.sources import Sources

        return Sources(
            OdometrySource(self.odometry),
            self.wheel_topic or None,
            self.dead_wheel_topic,
            self.reference_topic or None,
            self.reference_child or None,
            _own(self.reference_file, recording),
            _own(self.factors, recording),
            self.reference_sigma_m,
        )


def for_recording(template: str, recording: str) -> str:
    """``template`` with ``{stem}`` and ``{parent}`` replaced by the recording's name (without
    ``.mcap`` / ``.bag``) and directory: ``{parent}/{stem}.tum`` beside each recording."""
    path = Path(recording)
    stem = path.name.removesuffix(".mcap").removesuffix(".bag") or path.name
    return template.replace("{stem}", stem).replace("{parent}", str(path.parent))


def _own(template: str, recording: str) -> Path | None:
    """The file ``template`` names for ``recording`` (:func:`for_recording`); None for ""."""
    return Path(for_recording(template, recording)) if template else None


def check_robot_options(options: FleetOptions, robot: RobotDescription) -> None:
    """The options that depend on the robot, checked once against it before any job (each
    job's would be the same error, a row per recording).

    Raises:
        ConfigError: ``--odometry seed003`` for a robot without dead wheels (the single
            commands' line).
    """
    from omnical.errors import ConfigError

    if options.odometry == "seed003" and not robot.dead_wheels:
        msg = f"robot {robot.name} has no dead wheels: seed 003's odometry needs them"
        raise ConfigError(f"--odometry seed003: {msg}")


def check_files(options: FleetOptions) -> None:
    """Each file option the same for every recording (no ``{stem}`` / ``{parent}``) read and
    validated once, as its jobs read it: a bad one is one error before anything is written,
    not an error row per recording. A reference file's times (and positions), which are
    checked against each recording's start, are left to the jobs.

    Raises:
        ConfigError: the option, the file and what is wrong with it.
    """
    import numpy as np

    from omnical.calibration.factors_io import read_factors
    from omnical.errors import ConfigError, OmnicalError
    from omnical.evaluation.reference_input import BUILTIN_REFERENCES, read_reference
    from omnical.ips.beacons import load_beacon_map
    from omnical.recording.recording import Recording, Table

    def reference(path: str) -> None:
        try:  # a recording that starts at 0: its times are each recording's own to check
            read_reference(path, Recording({"/start": Table(np.zeros(1, np.int64), {})}))
        except ConfigError as err:
            if "within ±" not in str(err):
                raise

    reference_file = options.reference not in ("ground_truth", *BUILTIN_REFERENCES)
    checks: list[tuple[str, str, Callable[[str], object]]] = [
        ("--factors", options.factors, read_factors),
        ("--installed", options.installed, read_factors),
        ("--beacons", options.beacons, load_beacon_map),
        ("--reference-file", options.reference_file, reference),
        ("--reference", options.reference if reference_file else "", reference),
    ]
    for option, path, read in checks:
        if not path or "{stem}" in path or "{parent}" in path:
            continue  # not given, or each recording's own
        try:
            read(path)
        except OmnicalError as err:
            raise ConfigError(f"{option} {err}") from None


def reference_label(options: FleetOptions) -> str:
    """The reference the options name, for the report: ``/ground_truth``, the IPS, the topic,
    the file (its ``{stem}`` / ``{parent}`` template as given) or the built-in path; "" for
    ``locate``."""
    from omnical.recording.topics import GROUND_TRUTH

    if options.command == "locate":
        return ""
    if options.reference_topic:
        return options.reference_topic
    if options.reference_file:
        return options.reference_file
    if options.command == "calibrate":
        return IPS_REFERENCE
    return GROUND_TRUTH if options.reference == "ground_truth" else options.reference


@dataclass(frozen=True)
class FleetJob:
    """One recording of the fleet.

    Attributes:
        index: its place on the command line (the row's key).
        recording: the bag's path.
        name: its name in the table (the file name; made unique).
        out_dir: where the single command's outputs go.
        options: the command and its options.
    """

    index: int
    recording: str
    name: str
    out_dir: str
    options: FleetOptions


def fleet_job_name(paths: Sequence[Path]) -> list[str]:
    """A name per recording, unique in the fleet whatever the order of ``paths``: its file name
    without the extension, preceded by as many of its directories as tell it from the others
    (``robot1/run.mcap``, ``robot2/run.mcap``: ``robot1_run``, ``robot2_run``); names that
    still coincide (``x/run.mcap``, ``x/run.bag``) get a digest of the path.

    Raises:
        ConfigError: a recording given twice.
    """
    from omnical.errors import ConfigError

    normal = [Path(os.path.normpath(path)) for path in paths]
    seen: set[Path] = set()
    for path in normal:
        if path in seen:
            raise ConfigError(f"{path}: the same recording given twice")
        seen.add(path)
    parts = [
        [
            *(p for p in path.parent.parts if p != path.anchor),
            path.name.removesuffix(".mcap").removesuffix(".bag") or path.name,
        ]
        for path in normal
    ]
    depth = [1] * len(parts)
    while True:  # lengthen the names that clash (by case too: a case-blind file system)
        names = ["_".join(p[-d:]) for p, d in zip(parts, depth, strict=True)]
        clashes = _clashes(names)
        longer = [i for i in clashes if depth[i] < len(parts[i])]
        if not longer:
            break
        for i in longer:
            depth[i] += 1
    for i in clashes:
        digest = hashlib.sha256(str(normal[i]).encode()).hexdigest()[:8]
        names[i] = f"{names[i]}-{digest}"
    if _clashes(names):  # pragma: no cover - a clash of digests
        raise ConfigError("the recordings' names cannot be told apart: rename them")
    return names


def _clashes(names: Sequence[str]) -> list[int]:
    """The indices of the names another name equals (ignoring case)."""
    count = Counter(name.casefold() for name in names)
    return [i for i, name in enumerate(names) if count[name.casefold()] > 1]


def _number(value: float | int) -> str:
    """A figure as text that reads back to the same float (``repr``); "" for NaN."""
    if isinstance(value, int):
        return str(value)
    return "" if math.isnan(value) else repr(float(value))


def error_row(job: FleetJob, reason: str) -> dict[str, str]:
    """The row of a job that failed: its key, status ``error`` and the reason's first line."""
    line = reason.strip().splitlines()[0] if reason.strip() else "failed"
    return {
        INDEX: str(job.index),
        _NAME: job.name,
        _RECORDING: job.recording,
        STATUS: "error",
        REASON: line,
    }


@cache
def _robot(name: str) -> RobotDescription:
    from omnical.robot.loader import load_robot

    return load_robot(name)


def _locate(job: FleetJob, out: Path) -> dict[str, str]:
    """What ``omnical locate`` does (:func:`~omnical.reports.locate.locate_bag`): ``fixes.csv``
    (and, with ``--plot``, ``fixes.png``: the fixes over the beacon map, the vendor's beside).

    Raises:
        GeometryError: the fixes are not plausible, or (without ``--allow-poor``) poor, where
            ``omnical locate`` exits 3 after writing them: the files kept, the row an error.
    """
    import numpy as np

    from omnical.choices import LocateMethod
    from omnical.errors import GeometryError
    from omnical.ips.from_recording import write_fixes_csv
    from omnical.ips.solve.fixes import FixStatus
    from omnical.reports.locate import locate_bag

    o = job.options
    located = locate_bag(
        Path(job.recording),
        method=LocateMethod(o.method or "robust"),
        beacons=_own(o.beacons, job.recording),
        hedge_z_m=o.hedge_z_m,
        sigma_m=o.sigma_m,
        self_calibrate=o.self_calibrate,
        vendor=o.plot,
    )
    fixes = located.fixes
    write_fixes_csv(fixes, out / "fixes.csv")
    if o.plot:
        located.plot(out / "fixes.png")
    if located.not_plausible:  # as omnical locate says it, before its exit 3
        raise GeometryError(located.not_plausible)
    if located.poor and not o.allow_poor:  # as omnical locate, without --allow-poor
        msg = (
            f"only {100.0 * located.usable_fraction:.1f} % of the fixes are usable (ok or "
            "degraded); see the reason column of fixes.csv (--allow-poor: a row all the same)"
        )
        raise GeometryError(msg)
    counts = np.bincount(fixes.status, minlength=max(s.value for s in FixStatus) + 1)
    total = len(fixes)
    residual = fixes.residual_rms_m[np.isfinite(fixes.residual_rms_m)]
    cov = fixes.covariance_xy_m2
    sigma = np.sqrt(0.5 * (cov[:, 0, 0] + cov[:, 1, 1])) if total else np.zeros(0)
    sigma = sigma[np.isfinite(sigma)]
    worst = max((float(np.max(m.sigma_m)) for m in fixes.noise if len(m.sigma_m)), default=math.nan)
    return {
        "fixes": str(total),
        **{s.name.lower(): str(int(counts[s])) for s in FixStatus},
        "usable_fraction": _number(located.usable_fraction),
        "residual_median_m": _number(float(np.median(residual)) if residual.size else math.nan),
        "fix_sigma_median_m": _number(float(np.median(sigma)) if sigma.size else math.nan),
        "range_sigma_max_m": _number(worst),
    }


def _calibrate(job: FleetJob, out: Path) -> dict[str, str]:
    """What ``omnical calibrate estimate`` does (:mod:`omnical.reports.estimate`), for one
    recording: the factors, with the firmware header and the Wheeltec parameters beside
    ``factors.yaml``."""
    from omnical.choices import EstimationMethod
    from omnical.reports.estimate import read_for_estimate

    o = job.options
    inputs = read_for_estimate(
        [Path(job.recording)],
        robot=_robot(o.robot),
        sources=o.sources(job.recording),
        method=EstimationMethod(o.method) if o.method else None,
        installed=_own(o.installed, job.recording),
        beacons=_own(o.beacons, job.recording),
        hints=False,
    )
    result = inputs.estimate_and_write(out / "factors.yaml", "omnical fleet calibrate")
    said = {REFERENCE: IPS_REFERENCE, REFERENCE_TIMES: ""}
    if inputs.references:
        (ref,) = inputs.references  # its one recording's
        said = {REFERENCE: ref.label, REFERENCE_TIMES: ref.times}
    row = {"method": str(inputs.method), "held": ";".join(sorted(result.held)), **said}
    for name in _factor_fields():
        row[name] = _number(float(getattr(result.factors, name)))
        row[f"{name}_sigma"] = _number(float(result.sigma[name]))
    return row


def _evaluate(job: FleetJob, out: Path) -> dict[str, str]:
    """What ``omnical evaluate`` does (:func:`~omnical.reports.evaluate.evaluate_bag`, the
    recording read whole): the odometry and reference its options name (default the
    recording's ``/ground_truth``); ``metrics.json``, ``report.md`` and the figures.

    Raises:
        GeometryError: the recording does not follow the built-in ``--reference``, where
            ``omnical evaluate`` exits 3 after writing: the files kept, the row an error.
    """
    from omnical.choices import AlignMode, parse_choice
    from omnical.errors import GeometryError
    from omnical.reports.evaluate import evaluate_bag

    o = job.options
    evaluated = evaluate_bag(
        Path(job.recording),
        out,
        name=job.name,
        robot=_robot(o.robot),
        sources=o.sources(job.recording),
        reference=for_recording(o.reference, job.recording),
        align=parse_choice(AlignMode, o.align, "--align"),
        lean=False,
        hints=False,
    )
    if evaluated.off_path is not None:
        raise GeometryError(evaluated.off_path)
    row = {REFERENCE: evaluated.reference.label, REFERENCE_TIMES: evaluated.reference.times}
    for key in _ESTIMATES:
        t = evaluated.tracked.get(key)
        if t is None:
            continue
        row[f"{key}_rmse_m"] = _number(t.metrics.rmse_m)
        row[f"{key}_max_m"] = _number(t.metrics.max_m)
        row[f"{key}_final_m"] = _number(t.metrics.final_m)
        if key == "smoothed" and t.sigma_rms_m is not None:
            row["smoothed_sigma_m"] = _number(t.sigma_rms_m)
    return row


_RUN: Final[Mapping[str, Callable[[FleetJob, Path], dict[str, str]]]] = {
    "locate": _locate,
    "evaluate": _evaluate,
    "calibrate": _calibrate,
}


def run_fleet_job(job: FleetJob) -> dict[str, str]:
    """One recording through the single command's services; an error is the row's reason."""
    import warnings

    out = Path(job.out_dir)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a row says what went wrong; no worker chatter
            out.mkdir(parents=True, exist_ok=True)
            figures = _RUN[job.options.command](job, out)
    except Exception as err:  # an error is a row, never an abort
        with suppress(OSError):
            out.rmdir()  # nothing written: no empty directory left
        return error_row(job, failure(err))
    return {
        INDEX: str(job.index),
        _NAME: job.name,
        _RECORDING: job.recording,
        STATUS: "ok",
        REASON: "",
        **figures,
    }


run_fleet_chunk = partial(run_chunk, run_fleet_job)
"""The rows of a chunk of jobs (:func:`~omnical.fleet.runner.run_chunk`)."""

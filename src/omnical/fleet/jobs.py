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
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Final

from omnical.fleet.table import INDEX, REASON, STATUS, failure

if TYPE_CHECKING:
    from omnical.robot.description import RobotDescription

__all__ = [
    "FLEET_COMMANDS",
    "FleetJob",
    "FleetOptions",
    "error_row",
    "fleet_header",
    "fleet_job_name",
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
_ESTIMATES: Final = ("odometry", "ips", "multilateration", "smoothed")
_EVALUATE_COLUMNS: Final = (
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
        )
    return [INDEX, _NAME, _RECORDING, STATUS, REASON, *figures]


@dataclass(frozen=True)
class FleetOptions:
    """The single command's options, the same for every recording of the fleet.

    Attributes:
        command: ``locate``, ``evaluate`` or ``calibrate``.
        robot: robot preset or YAML path.
        method: locate's (robust, lsq, grid) or calibrate's (procedures, joint; "" chooses as
            ``calibrate estimate`` does).
        beacons: beacon map YAML ("" for the recording's).
        hedge_z_m: locate's ``--hedge-z`` (None: as locate finds it).
        sigma_m: locate's ``--sigma-m`` (None: learned).
        self_calibrate: locate without ``--no-self-calibration``.
        installed: calibrate's ``--installed`` factors.yaml ("" for none).
        align: evaluate's ``--align``.
    """

    command: str
    robot: str = "rosy-mecanum"
    method: str = ""
    beacons: str = ""
    hedge_z_m: float | None = None
    sigma_m: float | None = None
    self_calibrate: bool = True
    installed: str = ""
    align: str = "se2"


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
    """What ``omnical locate`` calls: read the three topics, locate, write ``fixes.csv``."""
    import numpy as np

    from omnical.bags.bag import read_bag
    from omnical.ips.beacons import load_beacon_map
    from omnical.ips.from_recording import locate, write_fixes_csv
    from omnical.ips.solve.fixes import FixStatus
    from omnical.recording.topics import BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG

    o = job.options
    recording = read_bag(Path(job.recording), (BEACON_RAW_DISTANCE, BEACONS_POS_A, HEDGE_POS_ANG))
    fixes, _ = locate(
        recording,
        beacons=load_beacon_map(o.beacons) if o.beacons else None,
        method=o.method or "robust",  # type: ignore[arg-type]
        hedge_z_m=o.hedge_z_m,
        range_sigma_m=o.sigma_m,
        self_calibrate=o.self_calibrate,
    )
    write_fixes_csv(fixes, out / "fixes.csv")
    counts = np.bincount(fixes.status, minlength=max(s.value for s in FixStatus) + 1)
    total = len(fixes)
    usable = counts[FixStatus.OK] + counts[FixStatus.DEGRADED]
    residual = fixes.residual_rms_m[np.isfinite(fixes.residual_rms_m)]
    cov = fixes.covariance_xy_m2
    sigma = np.sqrt(0.5 * (cov[:, 0, 0] + cov[:, 1, 1])) if total else np.zeros(0)
    sigma = sigma[np.isfinite(sigma)]
    worst = max((float(np.max(m.sigma_m)) for m in fixes.noise if len(m.sigma_m)), default=math.nan)
    return {
        "fixes": str(total),
        **{s.name.lower(): str(int(counts[s])) for s in FixStatus},
        "usable_fraction": _number(float(usable) / total if total else 0.0),
        "residual_median_m": _number(float(np.median(residual)) if residual.size else math.nan),
        "fix_sigma_median_m": _number(float(np.median(sigma)) if sigma.size else math.nan),
        "range_sigma_max_m": _number(worst),
    }


def _calibrate(job: FleetJob, out: Path) -> dict[str, str]:
    """What ``omnical calibrate estimate`` calls, for one recording: the factors, with the
    firmware header and the Wheeltec parameters beside ``factors.yaml``."""
    from omnical.bags.bag import read_bag
    from omnical.calibration.campaign import estimate_factors
    from omnical.calibration.export import write_c_header, write_wheeltec_params
    from omnical.calibration.factors_io import read_factors, write_factors
    from omnical.calibration.procedures.tracks import yaw_deadband_radps
    from omnical.ips.beacons import load_beacon_map
    from omnical.recording.topics import CMD_VEL

    o = job.options
    robot = _robot(o.robot)
    recording = read_bag(Path(job.recording))
    method = o.method or ("procedures" if recording.has(CMD_VEL) else "joint")
    result = estimate_factors(
        [recording],
        installed=read_factors(o.installed).factors if o.installed else None,
        method=method,  # type: ignore[arg-type]
        hedge_offset_m=robot.hedge_offset_m,
        beacons=load_beacon_map(o.beacons) if o.beacons else None,
        odom_yaw_deadband_radps=yaw_deadband_radps(robot.odom_yaw_resolution_radps),
    )
    unc = result.uncertainty()
    comment = f"omnical fleet calibrate: {job.recording} --method {method}"
    out.mkdir(parents=True, exist_ok=True)
    write_factors(out / "factors.yaml", result.factors, unc, comment=comment, held=result.held)
    write_c_header(out / "factors.h", result.factors, unc, held=result.held)
    write_wheeltec_params(out / "factors.wheeltec.yaml", result.factors, unc, held=result.held)
    row = {"method": str(method), "held": ";".join(sorted(result.held))}
    for name in _factor_fields():
        row[name] = _number(float(getattr(result.factors, name)))
        row[f"{name}_sigma"] = _number(float(result.sigma[name]))
    return row


def _evaluate(job: FleetJob, out: Path) -> dict[str, str]:
    """What ``omnical evaluate`` calls (reference: the recording's ``/ground_truth``):
    ``metrics.json``, ``report.md`` and the figures in the recording's directory."""
    from omnical.bags.bag import read_bag
    from omnical.choices import AlignMode, parse_choice
    from omnical.errors import RecordingError
    from omnical.evaluation.metrics import track_recording
    from omnical.recording.topics import DEAD_WHEELS, EVALUATED, GROUND_TRUTH, IMU_MAG
    from omnical.reports.tracking import write_evaluation

    o = job.options
    robot = _robot(o.robot)
    align = parse_choice(AlignMode, o.align, "--align")
    topics: tuple[str, ...] = EVALUATED
    if robot.dead_wheels:  # seed 003's estimate: dead-wheel encoders and magnetometer
        topics = (*topics, DEAD_WHEELS, IMU_MAG)
    recording = read_bag(Path(job.recording), topics)
    if not recording.has(GROUND_TRUTH):
        msg = f"{Path(job.recording).name} has no /ground_truth to evaluate against"
        raise RecordingError(msg)
    tracked = track_recording(
        recording,
        align=align.value,
        hedge_offset_m=robot.hedge_offset_m,
        dead_wheels=robot.dead_wheels,
        ground_truth_alone=True,
    )
    tracked = {k: t for k, t in tracked.items() if k != GROUND_TRUTH.lstrip("/")} or tracked
    write_evaluation(tracked, recording, out, name=job.name, align=align.value)
    row: dict[str, str] = {}
    for key in _ESTIMATES:
        t = tracked.get(key)
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


def run_fleet_chunk(jobs: Sequence[FleetJob]) -> list[dict[str, str]]:
    """The rows of a chunk of jobs, run one after another in the worker."""
    return [run_fleet_job(job) for job in jobs]

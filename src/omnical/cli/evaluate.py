"""``omnical evaluate``: tracking errors of a recording's estimates against a reference."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import AlignMode, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import Overwrite, Robot, choice_metavar
from omnical.cli.output import console, say

if TYPE_CHECKING:
    from collections.abc import Sequence

    from omnical.evaluation.metrics import Tracked
    from omnical.recording.recording import Recording
    from omnical.robot.description import DeadWheel

__all__ = ["evaluate"]


def evaluate(
    run: Annotated[Path, typer.Argument(help="Recording to evaluate.")],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output directory (metrics.json, figures).")
    ],
    reference: Annotated[
        str,
        typer.Option(
            help="REF.csv (t_s,x_m,y_m), lissajous, circle or square; default: /ground_truth."
        ),
    ] = "ground_truth",
    align: Annotated[
        str,
        typer.Option(
            metavar=choice_metavar(AlignMode),
            help="Alignment of every estimate but odometry (always aligned at its origin): "
            "none, origin or se2.",
        ),
    ] = AlignMode.SE2.value,
    robot: Robot = "rosy-mecanum",
    overwrite: Overwrite = False,
) -> None:
    """RMSE (Euclidean, x, y), max and final error of odometry, vendor IPS, multilateration and
    the smoothed trajectory.

    Multilateration counts trusted fixes only. The smoothed trajectory fuses the odometry, the
    trusted fixes and the gyro in a batch smoother with the robot's hedgehog lever arm and the
    IPS latency (estimated); it is the estimate to quote without ground truth. Prints a table,
    writes OUT/metrics.json, OUT/report.md and figures (paths, x(t) and y(t), speeds).
    """
    with handled_errors():
        mode = parse_choice(AlignMode, align, "--align")
        from omnical.reports.outputs import claim_directory

        claim_directory(out, overwrite=overwrite, writer="omnical evaluate")
        _evaluate(run, out, reference, mode, robot)


def _evaluate(run: Path, out: Path, reference: str, align: AlignMode, robot: str) -> None:
    from rich.markup import escape
    from rich.table import Table

    from omnical.recording.bag import read_bag
    from omnical.recording.topics import (
        BEACON_RAW_DISTANCE,
        BEACONS_POS_A,
        CMD_VEL,
        GROUND_TRUTH,
        HEDGE_POS_ANG,
        IMU,
        ODOM,
    )
    from omnical.robot.loader import load_robot

    description = load_robot(robot)
    # The estimates (odometry, vendor IPS, multilateration, the smoother's gyro), the reference
    # and the commands (reference timing, speed figures): not /hedge_quality nor /omnical/events.
    topics: tuple[str, ...] = (
        CMD_VEL,
        ODOM,
        IMU,
        GROUND_TRUTH,
        HEDGE_POS_ANG,
        BEACON_RAW_DISTANCE,
        BEACONS_POS_A,
    )
    if description.dead_wheels:  # seed 003's estimate: dead-wheel encoders and magnetometer
        topics = (*topics, "/dead_wheels", "/imu/mag")
    recording = read_bag(run, topics)
    results, figures = _evaluate_and_write(
        recording,
        run.name,
        out,
        reference,
        align,
        description.hedge_offset_m,
        description.dead_wheels,
    )
    table = Table(title=escape(f"{run.name}: tracking errors (m), alignment {align}"))
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
        sm = smoothed.smoothing
        say(
            f"smoothed (odometry + trusted fixes{' + gyro' if recording.has(IMU) else ''}): "
            f"RMSE {smoothed.metrics.rmse_m:.4f} m, its own 1σ {smoothed.sigma_rms_m or 0.0:.4f} m; "
            f"IPS latency {sm.latency_s * 1e3:.0f} ± {sm.latency_sigma_s * 1e3:.0f} ms"
        )
    say(f"wrote {out / 'metrics.json'}, {out / 'report.md'} and {figures} figures in {out}")


def _evaluate_and_write(
    recording: Recording,
    name: str,
    out: Path,
    reference: str,
    align: AlignMode,
    hedge_offset_m: tuple[float, float, float] | None = None,
    dead_wheels: Sequence[DeadWheel] = (),
) -> tuple[Mapping[str, Tracked], int]:
    """The calls of ``omnical evaluate`` into :mod:`omnical.evaluation` and :mod:`omnical.reports`.

    Writes ``out/metrics.json``, the figures and ``out/report.md``; returns the evaluation by
    estimate and the number of figures written.
    """
    from omnical.evaluation.metrics import track_recording
    from omnical.evaluation.reference_input import load_reference
    from omnical.reports.tracking import write_evaluation

    ref = None if reference == "ground_truth" else load_reference(reference, recording)
    with console().status("evaluating"):
        tracked = track_recording(
            recording,
            ref,
            align=align.value,
            hedge_offset_m=hedge_offset_m,
            dead_wheels=dead_wheels,
        )
    files = write_evaluation(tracked, recording, out, name=name, align=align.value)
    return tracked, len(files.figures)

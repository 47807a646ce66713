"""``omnical evaluate``: the errors of a recording's estimates against a reference.

Reference ``/ground_truth`` unless ``--reference``, ``--reference-file`` or ``--reference-topic``;
odometry ``/odom`` unless ``--wheel-topic`` or ``--odometry``; OUT is written whole.
"""

from __future__ import annotations

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
    WheelTopic,
)

if TYPE_CHECKING:
    from omnical.evaluation.metrics import Tracked
    from omnical.services.sources import Sources

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
        from omnical.services.sources import Sources

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


def _reference_label(reference: str, inputs: Sources) -> str:
    """The reference's name for the table's title."""
    if inputs.reference_topic is not None:
        child = f" → {inputs.reference_child}" if inputs.reference_child else ""
        return inputs.reference_topic + child
    if inputs.reference_file is not None:
        return inputs.reference_file.name
    from omnical.recording.topics import GROUND_TRUTH

    return GROUND_TRUTH if reference == "ground_truth" else Path(reference).name


def _evaluate(
    run: Path,
    out: Path,
    reference: str,
    align: AlignMode,
    robot: str,
    inputs: Sources,
    figures: bool = True,
) -> tuple[int, str | None]:
    """Evaluate ``run`` (:func:`~omnical.reports.evaluate.evaluate_bag`), print the table,
    write the files in ``out`` (the figures if ``figures``); the number of figures and, for a
    built-in reference the recording does not follow, why."""
    from rich.markup import escape
    from rich.table import Table

    from omnical.cli.output import voice
    from omnical.cli.robot_target import load_said_robot
    from omnical.reports.evaluate import evaluate_bag

    evaluated = evaluate_bag(
        run,
        out,
        name=run.name,
        robot=load_said_robot(robot),
        sources=inputs,
        reference=reference,
        align=align,
        figures=figures,
        voice=voice(),
    )
    label = _reference_label(reference, inputs)
    table = Table(
        title=escape(f"{run.name}: errors (m) against the reference ({label}), alignment {align}")
    )
    for col in ("estimate", "RMSE", "RMSE x", "RMSE y", "max", "final", "own 1σ"):
        table.add_column(col, justify="left" if col == "estimate" else "right")
    for name, t in evaluated.tracked.items():
        m = t.metrics
        values = (m.rmse_m, m.rmse_x_m, m.rmse_y_m, m.max_m, m.final_m)
        sigma = t.sigma_rms_m
        own = "" if sigma is None or name != "smoothed" else f"{sigma:.4f}"
        table.add_row(name, *(f"{v:.4f}" for v in values), own)
    console().print(table)
    smoothed = evaluated.tracked.get("smoothed")
    if smoothed is not None and smoothed.smoothing is not None:
        _say_smoothed(smoothed, evaluated.with_gyro)
    return evaluated.figures, evaluated.off_path


def _say_smoothed(smoothed: Tracked, with_gyro: bool) -> None:
    """What ``evaluate`` prints of the smoothed track: its RMSE, own 1σ and self-check, and a
    warning when it is not the estimate to quote."""
    from omnical.cli.output import warn

    sm = smoothed.smoothing
    if sm is None:  # pragma: no cover - the caller checks
        return
    arm = sm.hedge_offset_m
    check = sm.check
    failed = check is not None and not check.passed
    below_zero = sm.latency_s + 2.0 * sm.latency_sigma_s < 0.0
    impossible = " (negative: no IPS reports before it measures)" if below_zero else ""
    say(
        f"smoothed (odometry + trusted fixes{' + gyro' if with_gyro else ''}): "
        f"RMSE {smoothed.metrics.rmse_m:.4f} m, its own 1σ {smoothed.sigma_rms_m or 0.0:.4f} m; "
        f"IPS latency {sm.latency_s * 1e3:.0f} ± {sm.latency_sigma_s * 1e3:.0f} ms{impossible}; "
        f"lever arm ({arm[0]:+.3f}, {arm[1]:+.3f}) m"
        + (" (estimated)" if sm.shared_dict()["hedge_offset_x_m"][1] > 0.0 else " (given)")
        + ("; the self-check failed: neither is to be used" if failed else "")
    )
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

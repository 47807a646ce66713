"""``omnical evaluate``: tracking errors of a recording's estimates against a reference."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from omnical.choices import AlignMode, parse_choice
from omnical.cli.errors import handled_errors
from omnical.cli.options import choice_metavar
from omnical.cli.output import console

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from omnical.evaluation.metrics import TrackingMetrics
    from omnical.recording.recording import Recording

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
) -> None:
    """RMSE (Euclidean, x, y), max and final error of odometry, vendor IPS and multilateration.

    Prints them as a table, writes OUT/metrics.json and figures (paths, x(t) and y(t), speeds).
    """
    with handled_errors():
        mode = parse_choice(AlignMode, align, "--align")
        _evaluate(run, out, reference, mode)


def _evaluate(run: Path, out: Path, reference: str, align: AlignMode) -> None:
    from rich.table import Table

    from omnical.recording.bag import read_bag

    recording = read_bag(run)
    results, figures = _evaluate_and_write(recording, run.name, out, reference, align)
    table = Table(title=f"{run.name}: tracking errors (m), alignment {align}")
    for col in ("estimate", "RMSE", "RMSE x", "RMSE y", "max", "final"):
        table.add_column(col, justify="left" if col == "estimate" else "right")
    for name, m in results.items():
        values = (m.rmse_m, m.rmse_x_m, m.rmse_y_m, m.max_m, m.final_m)
        table.add_row(name, *(f"{v:.4f}" for v in values))
    console().print(table)
    console().print(f"wrote {out / 'metrics.json'} and {figures} figures in {out}")


def _evaluate_and_write(
    recording: Recording, name: str, out: Path, reference: str, align: AlignMode
) -> tuple[Mapping[str, TrackingMetrics], int]:
    """The calls of ``omnical evaluate`` into :mod:`omnical.evaluation` and :mod:`omnical.viz`.

    Writes ``out/metrics.json`` and the figures; returns the metrics by estimate and the number
    of figures written.
    """
    import numpy as np

    from omnical.evaluation.metrics import metrics_json, track_recording
    from omnical.evaluation.reference_input import load_reference
    from omnical.viz.trajectory import plot_position_time, plot_speeds, plot_tracking_paths

    ref = None if reference == "ground_truth" else load_reference(reference, recording)
    with console().status("evaluating"):
        tracked = track_recording(recording, ref, align=align.value)
    out.mkdir(parents=True, exist_ok=True)
    results = {estimate: t.metrics for estimate, t in tracked.items()}
    (out / "metrics.json").write_text(metrics_json(results), encoding="utf-8")
    first = next(iter(tracked.values()))
    ref_xy = first.association.reference_xy_m

    def aligned(estimate: str) -> ArrayLike | None:
        return tracked[estimate].alignment.xy_m if estimate in tracked else None

    plot_tracking_paths(
        out / "path.png",
        reference_xy_m=ref_xy,
        odometry_xy_m=aligned("odometry"),
        ips_xy_m=aligned("ips"),
        multilateration_xy_m=aligned("multilateration"),
        title=f"{name}: paths against the reference",
    )
    plot_position_time(
        out / "xy-time.png",
        reference=(first.association.t_s, ref_xy),
        estimates={n: (t.association.t_s, t.alignment.xy_m) for n, t in tracked.items()},
        title=f"{name}: x(t) and y(t)",
    )
    figures = 2
    if recording.has("/cmd_vel"):
        cmd = recording.topic("/cmd_vel")
        t0 = recording.start_ns
        odom = recording.topic("/odom") if recording.has("/odom") else None
        plot_speeds(
            out / "speeds.png",
            cmd_t_s=cmd.t_s(t0),
            cmd_twist=np.column_stack([cmd["vx_mps"], cmd["vy_mps"], cmd["wz_radps"]]),
            odom_t_s=odom.t_s(t0) if odom is not None else None,
            odom_twist=np.column_stack([odom["vx_mps"], odom["vy_mps"], odom["wz_radps"]])
            if odom is not None
            else None,
            title=f"{name}: speeds",
        )
        figures += 1
    return results, figures

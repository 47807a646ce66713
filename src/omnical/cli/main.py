"""``omnical``: simulate, inspect, export, and the demo."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli import commands
from omnical.cli.calibrate import register as register_calibrate
from omnical.cli.errors import user_errors

app = typer.Typer(
    name="omnical",
    help="Kinematics, digital twin, indoor positioning and calibration for omnidirectional robots.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


@app.command()
def simulate(
    script: Annotated[
        str, typer.Argument(help="Motion script YAML, or a built-in name (tour, straight-10m).")
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out", "-o", help="Recording to write: RUN.mcap (ROS 2) or RUN.bag (ROS 1)."
        ),
    ],
    robot: Annotated[
        str, typer.Option(help="Robot preset (rosy-mecanum, omni-x) or robot YAML.")
    ] = "rosy-mecanum",
    twin: Annotated[str, typer.Option(help="Twin YAML, or 'default' / 'ideal'.")] = "default",
    seed: Annotated[int, typer.Option(help="Random seed (same seed, same run).")] = 0,
    beacons: Annotated[
        Path | None, typer.Option(help="Beacon map YAML (default: seed 000 Table 3).")
    ] = None,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace an existing recording.")
    ] = False,
) -> None:
    """Run a motion script on the digital twin and record it as a ROS bag."""
    with user_errors():
        commands.simulate(script, out, robot, twin, seed, beacons, overwrite)


@app.command()
def info(
    run: Annotated[
        Path, typer.Argument(help="Recording (ROS 2 bag directory or .mcap, ROS 1 .bag).")
    ],
) -> None:
    """Topics, counts, duration and distance travelled of a recording."""
    with user_errors():
        commands.info(run)


@app.command()
def export(
    run: Annotated[Path, typer.Argument(help="Recording to export.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")],
    fmt: Annotated[str, typer.Option("--format", "-f", help="csv or tum.")] = "csv",
) -> None:
    """Export a recording to CSV (one file per topic) or TUM trajectory files."""
    with user_errors():
        commands.export(run, out, fmt)


@app.command()
def locate(
    run: Annotated[Path, typer.Argument(help="Recording with /beacon_raw_distance.")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Fixes CSV to write.")],
    method: Annotated[
        str, typer.Option(help="robust (default), lsq, or grid (seed 000's search).")
    ] = "robust",
    plot: Annotated[Path | None, typer.Option(help="PNG of the fixes over the beacon map.")] = None,
    beacons: Annotated[
        Path | None, typer.Option(help="Beacon map YAML (default: the recording's).")
    ] = None,
    hedge_z: Annotated[
        float | None, typer.Option(help="Hedgehog height, m (default: map or vendor).")
    ] = None,
) -> None:
    """Multilaterate every raw-distance burst of a recording, with a confidence for each fix."""
    with user_errors():
        commands.locate(run, out, method, plot, beacons, hedge_z)


@app.command()
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
        str, typer.Option(help="none, origin or se2 (map-frame estimates; odometry: origin).")
    ] = "se2",
) -> None:
    """Tracking errors (seed 000 Table 4) of odometry, vendor IPS and multilateration, with figures."""
    with user_errors():
        commands.evaluate(run, out, reference, align)


@app.command()
def demo(
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory.")] = Path(
        "omnical-out"
    ),
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """The main job: the standard tour on the rosy-mecanum twin, odometry against ground truth."""
    with user_errors():
        commands.demo(out, seed)


register_calibrate(app)


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":
    main()

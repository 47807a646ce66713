"""The CLI commands' bodies: parse, call the library, print. No numerics here."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table as RichTable

from omnical.errors import ConfigError
from omnical.experiment.script import load_script
from omnical.ips.beacons import BeaconMap, load_beacon_map
from omnical.ips.from_recording import locate as locate_recording_fixes
from omnical.ips.from_recording import write_fixes_csv
from omnical.ips.solve import FixStatus, Method
from omnical.recording.bag import bag_location, read_bag, write_bag
from omnical.recording.export import export_csv, export_tum
from omnical.recording.recording import Recording
from omnical.recording.summary import summarize
from omnical.robot.loader import load_robot
from omnical.twin.params import load_twin
from omnical.twin.session import simulate_run

console = Console(highlight=False)


@contextmanager
def _progress(label: str) -> Iterator[Callable[[float, float], None]]:
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} s robot time"),
        TimeRemainingColumn(),
        console=console,
        transient=True,
    ) as progress:
        task = progress.add_task(label, total=1.0)

        def update(done_s: float, total_s: float) -> None:
            progress.update(task, completed=done_s, total=max(total_s, 1e-9))

        yield update


def _simulate(
    script: str, robot_name: str, twin: str, seed: int, beacons: BeaconMap | None
) -> Recording:
    robot = load_robot(robot_name)
    params = load_twin(twin, robot)
    compiled = load_script(script, robot.limits)
    with _progress(f"simulating {compiled.name}") as tick:
        return simulate_run(compiled, robot, params, seed=seed, beacons=beacons, on_tick=tick)


def simulate(
    script: str, out: Path, robot: str, twin: str, seed: int, beacons: Path | None, overwrite: bool
) -> None:
    """``omnical simulate``."""
    if not overwrite and bag_location(out).exists():
        msg = f"{bag_location(out)}: already exists; choose another --out or pass --overwrite"
        raise ConfigError(msg)
    bmap = load_beacon_map(beacons) if beacons is not None else None
    recording = _simulate(script, robot, twin, seed, bmap)
    written = write_bag(recording, out, overwrite=overwrite)
    console.print(
        f"wrote {written} ({recording.duration_s:.1f} s, {sum(len(t) for t in recording.tables.values())} messages)"
    )


def info(run: Path) -> None:
    """``omnical info``."""
    summary = summarize(read_bag(run))
    table = RichTable(title=f"{run}")
    table.add_column("topic")
    table.add_column("messages", justify="right")
    table.add_column("rate (Hz)", justify="right")
    for topic in summary.topics:
        table.add_row(
            topic.name, str(topic.count), f"{topic.rate_hz:.1f}" if topic.rate_hz else "-"
        )
    console.print(table)
    console.print(f"duration: {summary.duration_s:.2f} s")
    if summary.distance_odom_m is not None:
        console.print(f"distance travelled (odometry): {summary.distance_odom_m:.3f} m")
    if summary.distance_ground_truth_m is not None:
        console.print(f"distance travelled (ground truth): {summary.distance_ground_truth_m:.3f} m")


def export(run: Path, out: Path, fmt: str) -> None:
    """``omnical export``."""
    exporters = {"csv": export_csv, "tum": export_tum}
    if fmt not in exporters:
        msg = f"--format: unknown format {fmt!r}; choose csv or tum"
        raise ConfigError(msg)
    recording = read_bag(run)
    for path in exporters[fmt](recording, out):
        console.print(f"wrote {path}")


def locate(
    run: Path,
    out: Path,
    method: str,
    plot: Path | None,
    beacons: Path | None,
    hedge_z: float | None,
) -> None:
    """``omnical locate``."""
    methods: dict[str, Method] = {"robust": "robust", "lsq": "lsq", "grid": "grid"}
    if method not in methods:
        msg = f"--method: unknown method {method!r}; choose robust, lsq or grid"
        raise ConfigError(msg)
    recording = read_bag(run)
    bmap = load_beacon_map(beacons) if beacons is not None else None
    with console.status(f"multilaterating ({method})"):
        fixes, used_map = locate_recording_fixes(
            recording,
            beacons=bmap,
            method=methods[method],
            hedge_z_m=hedge_z,
        )
    write_fixes_csv(fixes, out)
    counts = {s.name.lower(): int((fixes.status == s).sum()) for s in FixStatus}
    console.print(
        f"wrote {out}: {len(fixes)} fixes " + ", ".join(f"{k} {v}" for k, v in counts.items())
    )
    if plot is not None:
        from omnical.viz.ips import plot_fixes

        vendor = None
        if recording.has("/hedge_pos_ang"):
            pos = recording.topic("/hedge_pos_ang")
            ok = (pos["flags"] & 1) == 0
            vendor = np.column_stack([pos["x_m"][ok], pos["y_m"][ok]])
        plot_fixes(
            fixes, used_map, plot, vendor_xy=vendor, title=f"{run.name}: {method} multilateration"
        )
        console.print(f"wrote {plot}")


def evaluate(run: Path, out: Path, reference: str, align: str) -> None:
    """``omnical evaluate``."""
    from omnical.evaluation.alignment import ALIGN_MODES
    from omnical.evaluation.metrics import metrics_json, track_recording
    from omnical.evaluation.reference_input import load_reference
    from omnical.viz.trajectory import plot_position_time, plot_speeds, plot_tracking_paths

    if align not in ALIGN_MODES:
        msg = f"--align: unknown mode {align!r}; choose none, origin or se2"
        raise ConfigError(msg)
    recording = read_bag(run)
    ref = None if reference == "ground_truth" else load_reference(reference, recording)
    with console.status("evaluating"):
        tracked = track_recording(recording, ref, align=align)  # type: ignore[arg-type]
    out.mkdir(parents=True, exist_ok=True)
    results = {name: t.metrics for name, t in tracked.items()}
    (out / "metrics.json").write_text(metrics_json(results), encoding="utf-8")
    table = RichTable(title=f"{run.name}: tracking errors (m), alignment {align}")
    for col in ("estimate", "RMSE", "RMSE x", "RMSE y", "max", "final"):
        table.add_column(col, justify="left" if col == "estimate" else "right")
    for name, m in results.items():
        table.add_row(
            name, *(f"{v:.4f}" for v in (m.rmse_m, m.rmse_x_m, m.rmse_y_m, m.max_m, m.final_m))
        )
    console.print(table)
    first = next(iter(tracked.values()))
    ref_xy = first.association.reference_xy_m
    figs = [
        plot_tracking_paths(
            out / "path.png",
            reference_xy_m=ref_xy,
            odometry_xy_m=tracked["odometry"].alignment.xy_m if "odometry" in tracked else None,
            ips_xy_m=tracked["ips"].alignment.xy_m if "ips" in tracked else None,
            multilateration_xy_m=tracked["multilateration"].alignment.xy_m
            if "multilateration" in tracked
            else None,
            title=f"{run.name}: paths against the reference",
        ),
        plot_position_time(
            out / "xy-time.png",
            reference=(first.association.t_s, ref_xy),
            estimates={n: (t.association.t_s, t.alignment.xy_m) for n, t in tracked.items()},
            title=f"{run.name}: x(t) and y(t)",
        ),
    ]
    if recording.has("/cmd_vel"):
        cmd = recording.topic("/cmd_vel")
        t0 = recording.start_ns
        odom = recording.topic("/odom") if recording.has("/odom") else None
        figs.append(
            plot_speeds(
                out / "speeds.png",
                cmd_t_s=cmd.t_s(t0),
                cmd_twist=np.column_stack([cmd["vx_mps"], cmd["vy_mps"], cmd["wz_radps"]]),
                odom_t_s=odom.t_s(t0) if odom is not None else None,
                odom_twist=np.column_stack([odom["vx_mps"], odom["vy_mps"], odom["wz_radps"]])
                if odom is not None
                else None,
                title=f"{run.name}: speeds",
            )
        )
    console.print(f"wrote {out / 'metrics.json'} and {len(figs)} figures in {out}")


def demo(out: Path, seed: int) -> None:
    """``omnical demo``: uncalibrated Lissajous, calibration campaign, calibrated Lissajous, report."""
    from omnical.demo import run_demo

    with console.status("omnical demo") as status:
        result = run_demo(
            out, seed=seed, progress=lambda msg: status.update(f"omnical demo: {msg}")
        )
    before, after = result.before, result.after
    table = RichTable(title="open-loop Lissajous on the rosy-mecanum twin (RMSE, m)")
    table.add_column("estimate")
    table.add_column("uncalibrated", justify="right")
    table.add_column("calibrated", justify="right")
    for name in before:
        if name in after:
            table.add_row(name, f"{before[name].rmse_m:.4f}", f"{after[name].rmse_m:.4f}")
    console.print(table)
    console.print(
        f"ground truth: {result.improvement:.1f}x lower RMSE after calibration (seed 000: 6.5x)"
    )
    for p in result.paths:
        console.print(
            f"closed loop, {p.name}: final error {p.final_vs_ground_truth_m * 100:.1f} cm (ground truth)"
        )
    console.print(f"report: {result.report_path}")

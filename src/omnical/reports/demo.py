"""The demo's files: ``report.md``, its figures, the Lissajous bags and the campaign's directory.

:func:`write_demo` writes what :func:`omnical.services.demo.run_demo` found under one directory.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from omnical.bags.bag import write_bag
from omnical.estimation.smoother import SmoothedTrack
from omnical.evaluation.metrics import (
    GROUND_TRUTH_KEY,
    IPS_KEY,
    ODOMETRY_KEY,
    SMOOTHED_KEY,
)
from omnical.paper import SEED000_IMPROVEMENT, SEED000_TABLE4
from omnical.reports.campaign import CampaignFiles, write_campaign
from omnical.reports.markdown import (
    Block,
    FigureLink,
    MarkdownTable,
    Section,
    write_markdown_report,
)
from omnical.reports.navigation import navigation_chapter_section
from omnical.reports.outputs import Notify, claim_directory
from omnical.reports.seed003 import seed003_sections
from omnical.reports.tables import factors_table, metrics_table, table4
from omnical.reports.tracking import tracking_figures
from omnical.services.demo import LISSAJOUS_CENTRE_MAP_M, DemoResult, LissajousRun, PathRun

__all__ = ["DemoFiles", "write_demo"]

Say = Callable[[str], None]


@dataclass(frozen=True)
class DemoFiles:
    """What :func:`write_demo` wrote.

    Attributes:
        report: ``report.md``.
        figures: the demo's own figures (the campaign's are in ``calibration.files``).
        recordings: the Lissajous bags.
        calibration: the campaign's directory.
    """

    report: Path
    figures: tuple[Path, ...]
    recordings: tuple[Path, ...]
    calibration: CampaignFiles


def _lissajous_figures(run: LissajousRun, fig_dir: Path) -> list[Path]:
    return tracking_figures(
        run.tracked,
        run.recording,
        fig_dir,
        stem=f"lissajous-{run.label}-",
        title=f"Lissajous, {run.label} kinematics (seed 000 Figures 16–17, seed 001 Figure 9)",
        frame="map",
        over_time=(ODOMETRY_KEY, IPS_KEY, GROUND_TRUTH_KEY),
    )


def _path_figure(path: PathRun, fig_dir: Path) -> Path:
    from omnical.reports.figures.paths import plot_closed_loop

    return plot_closed_loop(
        fig_dir / f"closed-loop-{path.slug}.png",
        waypoints_xy_m=path.outline_xy_m,
        odometry_xy_m=path.run.odometry_path()[:, 1:3],
        truth_xy_m=path.run.ground_truth_path()[:, 1:3],
        title=f"{path.name}, calibrated twin",
    )


def _result_section(result: DemoResult) -> Section:
    before, after = result.before, result.after
    gt_b, gt_a = before[GROUND_TRUTH_KEY], after[GROUND_TRUTH_KEY]
    paper_b = SEED000_TABLE4["uncalibrated"]["ips"][0]
    paper_a = SEED000_TABLE4["calibrated"]["ips"][0]
    # beside the paper's numbers, the paper's convention: per axis, sqrt((x² + y²) / 2)
    lines = [
        (
            "- Ground-truth RMSE of the open-loop Lissajous, per axis as seed 000 Table 4 "
            f"(√((x² + y²)/2)): **{gt_b.rmse_per_axis_m:.4f} m → {gt_a.rmse_per_axis_m:.4f} m, "
            f"{result.improvement:.1f}× lower** (Euclidean {gt_b.rmse_m:.4f} → "
            f"{gt_a.rmse_m:.4f} m); seed 000 saw {paper_b:.4f} → {paper_a:.4f} m per axis from "
            f"its IPS, {SEED000_IMPROVEMENT:.1f}×."
        )
    ]
    measured = result.measured_improvement
    if measured is not None:
        sm_b, sm_a = before[SMOOTHED_KEY], after[SMOOTHED_KEY]
        checks = [
            _smoother_check(run.tracked[SMOOTHED_KEY].smoothing)
            for run in (result.uncalibrated, result.calibrated)
        ]
        quotable = all(ok for ok, _ in checks)
        lines.append(
            f"- **Measured from the sensors alone** (IPS fixes + wheel odometry + gyro, batch "
            f"smoother with the hedgehog lever arm and the IPS latency): "
            f"{sm_b.rmse_per_axis_m:.4f} m → {sm_a.rmse_per_axis_m:.4f} m per axis (Euclidean "
            f"{sm_b.rmse_m:.4f} → {sm_a.rmse_m:.4f} m), **{measured:.1f}× lower** (the truth: "
            f"{result.improvement:.1f}×). Its self-check against its own fixes: before "
            f"{checks[0][1]}, after {checks[1][1]}; "
            + (
                "both passed, so this is what a user without ground truth could publish."
                if quotable
                else "a check failed, so a user without ground truth should not quote it."
            )
        )
    if IPS_KEY in before and IPS_KEY in after:
        ips_b, ips_a = before[IPS_KEY], after[IPS_KEY]
        lines.append(
            f"- Vendor IPS RMSE: {ips_b.rmse_per_axis_m:.4f} m → {ips_a.rmse_per_axis_m:.4f} m "
            f"per axis (Euclidean {ips_b.rmse_m:.4f} → {ips_a.rmse_m:.4f} m, "
            f"{ips_b.rmse_m / ips_a.rmse_m:.1f}×)."
        )
    if ODOMETRY_KEY in before and ODOMETRY_KEY in after:
        odo_b = SEED000_TABLE4["uncalibrated"]["odometry"][0]
        odo_a = SEED000_TABLE4["calibrated"]["odometry"][0]
        lines.append(
            "- Wheel odometry against the reference (Table 4's per-axis position RMSE): "
            f"{before[ODOMETRY_KEY].rmse_per_axis_m * 1e3:.1f} mm uncalibrated, "
            f"{after[ODOMETRY_KEY].rmse_per_axis_m * 1e3:.1f} mm calibrated (seed 000: "
            f"{odo_b * 1e3:.1f} and {odo_a * 1e3:.1f} mm): what the vehicle controller's "
            "wheel-speed loop leaves of the commanded motion."
        )
    campaign = result.campaign
    lines.append(
        f"- Calibration: {len(campaign.iterations)} iterations, "
        f"{'converged' if campaign.converged else 'not converged'}; "
        "full report: [calibration/report.md](calibration/report.md)."
    )
    return Section("Result", ("\n".join(lines),))


def _paths_table(paths: tuple[PathRun, ...]) -> MarkdownTable:
    return MarkdownTable(
        (
            "path",
            "final error vs odometry (m)",
            "final error vs ground truth (m)",
            "duration (s)",
        ),
        tuple(
            (
                p.name,
                f"{p.final_vs_odometry_m:.4f}",
                f"{p.final_vs_ground_truth_m:.4f}",
                f"{p.duration_s:.1f}",
            )
            for p in paths
        ),
    )


def demo_sections(
    result: DemoResult,
    lissajous_figures: list[Path],
    path_figures: list[Path],
    chapters: list[Section],
) -> list[Section]:
    """The demo report as sections."""
    intro = (
        "The twin's truth is seed 000 Table 2 (signs in docs/CONVENTIONS.md), with slip, "
        "backlash, encoder quantisation, a hedgehog 5 cm off centre and a Marvelmind IPS with "
        "5 % non-line-of-sight ranges. The Lissajous curve (seed 000 Eq. 5–6, S = 1 m, "
        "trapezoidal phase profile, robot turned 90° counter-clockwise) is driven open loop "
        f"around {LISSAJOUS_CENTRE_MAP_M} in the beacon map, before and after the calibration "
        "campaign. Estimates are compared with the reference placed where the robot starts: "
        "map-frame estimates unaligned, odometry aligned at the start (its frame starts at the "
        "robot)."
    )
    campaign = result.campaign
    tracking: list[Block] = [
        (
            'Seed 000\'s "position" row is sqrt((RMSE_x² + RMSE_y²)/2); the Euclidean RMSE is '
            "√2 larger (below)."
        ),
        table4(result.before, result.after),
        "Uncalibrated, all measures (Euclidean position RMSE):",
        metrics_table(result.before),
        "Calibrated:",
        metrics_table(result.after),
        (
            "Odometry tracks the reference in both runs — it is the wheel odometry that the "
            "open-loop commands follow — while the robot itself (ground truth, IPS, "
            "multilateration) does not until it is calibrated, as in the paper."
        ),
        *(FigureLink(f, f.stem) for f in lissajous_figures),
    ]
    closed: list[Block] = [
        (
            "Closed against the wheel odometry, as in the papers. Final error = distance from "
            "the final pose to the last waypoint."
        ),
        _paths_table(result.paths),
        *(FigureLink(f, f.stem) for f in path_figures),
    ]
    return [
        Section("About", (intro,)),
        _result_section(result),
        Section(
            "Correction factors (seed 000 Table 2)",
            (factors_table(campaign.factors, campaign.sigma, campaign.truth),),
        ),
        Section("Tracking the Lissajous (seed 000 Table 4)", tuple(tracking)),
        Section("Closed-loop paths on the calibrated twin (seed 001)", tuple(closed)),
        *chapters,
    ]


def write_demo(
    result: DemoResult,
    out_dir: str | Path,
    *,
    on_progress: Say | None = None,
    overwrite: bool = False,
    notify: Notify | None = None,
) -> DemoFiles:
    """Write the demo's report, figures and recordings under ``out_dir`` (docs/DESIGN-NOTES.md),
    swapped in whole (:meth:`omnical.reports.outputs.DirectoryOutput.staged`).

    Args:
        result: the demo.
        out_dir: the directory.
        on_progress: receives one line per chapter written.
        overwrite: replace an earlier omnical output in ``out_dir``.
        notify: told where an unfinished output was kept (``OUT.partial``).

    Raises:
        OutputError: ``out_dir`` is a file, holds someone else's files, or an earlier output
            without ``overwrite``.
        RecordingError: a file cannot be written.
    """
    say = on_progress or (lambda _line: None)
    claimed = claim_directory(out_dir, overwrite=overwrite, writer="omnical demo", notify=notify)
    with claimed.staged(notify) as out:
        files = _write_demo(result, out, say)
    final = claimed.final
    return DemoFiles(
        final(files.report),
        tuple(map(final, files.figures)),
        tuple(map(final, files.recordings)),
        files.calibration.moved(final),
    )


def _write_demo(result: DemoResult, out: Path, say: Say) -> DemoFiles:
    """Write the demo's files in ``out``."""
    fig_dir, rec_dir = out / "figures", out / "recordings"
    say("recordings")
    bags = tuple(
        write_bag(run.recording, rec_dir / f"lissajous-{run.label}.mcap")
        for run in (result.uncalibrated, result.calibrated)
    )
    say("calibration report")
    calibration = write_campaign(result.campaign, out / "calibration", result.robot)
    say("figures")
    liss = _lissajous_figures(result.uncalibrated, fig_dir) + _lissajous_figures(
        result.calibrated, fig_dir
    )
    paths = [_path_figure(p, fig_dir) for p in result.paths]
    seed003, seed003_figures = seed003_sections(result.seed003, fig_dir)
    chapters = [
        Section(
            "Seed 003 on its own robot, the omni-X twin",
            (
                (
                    "Seed 003's motor tuning and its four tests on the omni-X twin, closed on the "
                    "dead-wheel + IMU + magnetometer estimate (Eq. 6–19), the paper's errors beside "
                    "the estimate's and the ground truth's (`omnical seed003` writes this alone)."
                ),
                *seed003,
            ),
        )
    ]
    if result.navigation is not None:
        say("navigation figures")
        chapters.append(navigation_chapter_section(result.navigation, fig_dir))
    say("report")
    report = write_markdown_report(
        out,
        "omnical demo — seeds 000, 001 and 003 on the twins",
        demo_sections(result, liss, paths, chapters),
    )
    return DemoFiles(report, tuple(liss + paths + seed003_figures), bags, calibration)


def _smoother_check(smoothing: SmoothedTrack | None) -> tuple[bool, str]:
    """Whether the smoothed track is the estimate to quote, and its check in a phrase."""
    if smoothing is None or smoothing.check is None:
        return False, "not run"
    check = smoothing.check
    verdict = "passed" if smoothing.trustworthy else "failed"
    return smoothing.trustworthy, (
        f"{verdict} (χ²/dof {check.fix_chi2_per_dof:.2f}, "
        f"{check.fixes_in_band_95 * 100:.0f} % of fixes in the 95 % band)"
    )

"""The campaign's files: factors, firmware exports, recordings, figures and ``report.md``.

:func:`write_campaign` writes what :func:`~omnical.calibration.campaign.run_campaign` found under
one directory: ``factors.yaml``, the C header, Wheeltec parameters, bags, figures, the report.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from omnical.bags.bag import write_bag
from omnical.calibration.campaign import CampaignResult
from omnical.calibration.export import write_c_header, write_wheeltec_params
from omnical.calibration.factors_io import write_factors
from omnical.calibration.measures import MEASURE_SPECS
from omnical.calibration.procedures.tracks import (
    hedge_offset_xy,
    move_arcs,
    procedure_tracks,
    yaw_deadband_radps,
)
from omnical.ips.beacons import BeaconMap
from omnical.ips.from_recording import beacon_map_of
from omnical.kinematics.factors import Factor
from omnical.reports.markdown import Block, FigureLink, Section, write_markdown_report
from omnical.reports.outputs import Notify, claim_directory
from omnical.reports.tables import (
    crosstalk_table,
    factors_table,
    iterations_table,
    measures_table,
    validation_table,
)
from omnical.robot.description import RobotDescription

__all__ = [
    "CampaignFiles",
    "campaign_sections",
    "procedure_measured",
    "write_campaign",
]

Say = Callable[[str], None]


@dataclass(frozen=True)
class CampaignFiles:
    """What :func:`write_campaign` wrote.

    Attributes:
        out_dir: the directory.
        report: ``report.md``.
        files: every file by role (``factors``, ``header``, ``ros_params``, ``report``,
            ``figure:<name>``, ``recording:<name>``).
        wall_time_s: time spent writing, s.
    """

    out_dir: Path
    report: Path
    files: Mapping[str, Path]
    wall_time_s: float

    def by_kind(self, kind: str) -> dict[str, Path]:
        """The files of one kind (``figure`` or ``recording``) by name."""
        prefix = f"{kind}:"
        return {k.removeprefix(prefix): p for k, p in self.files.items() if k.startswith(prefix)}

    def moved(self, to: Callable[[Path], Path]) -> CampaignFiles:
        """The same files where ``to`` says they are now (written in a staging directory)."""
        files = {role: to(path) for role, path in self.files.items()}
        return CampaignFiles(to(self.out_dir), to(self.report), files, self.wall_time_s)


_FIGURE_CAPTIONS = {
    "iter1-rotation": "Rotation procedure, first iteration (as seed 000 Figure 8).",
    "iter2-rotation": "Rotation procedure, second iteration (as seed 000 Figure 9).",
    "iter1-longitudinal": "Longitudinal procedure, first iteration (as seed 000 Figure 10).",
    "validation-longitudinal": (
        "Longitudinal procedure with the final factors installed (as seed 000 Figure 11)."
    ),
    "iter1-lateral": "Lateral procedure, first iteration (as seed 000 Figure 12).",
    "validation-lateral": (
        "Lateral procedure with the final factors installed (as seed 000 Figure 13)."
    ),
    "validation-rotation": "Rotation procedure with the final factors installed.",
    "measures": "The paper's measures before and after.",
}


def _caption(name: str) -> str:
    if name in _FIGURE_CAPTIONS:
        return _FIGURE_CAPTIONS[name]
    stage, _, kind = name.partition("-")
    if stage.startswith("iter") and kind:
        return f"{kind.capitalize()} procedure, iteration {stage.removeprefix('iter')}."
    return name


def _tolerance_text(result: CampaignResult) -> str:
    tol = result.tolerance
    return (
        f"{100 * tol.scale_relative:.2g} % for the scalings, "
        f"{1e3 * tol.crosstalk_rad_per_m:.2g} mrad/m for the cross-talks"
    )


def _relative(path: Path, base: Path) -> str:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return path.as_posix()


def campaign_sections(
    result: CampaignResult,
    figures: Mapping[str, Path] | None = None,
    files: Mapping[str, Path] | None = None,
    out_dir: Path | None = None,
) -> list[Section]:
    """The report of a campaign as sections (docs/DESIGN-NOTES.md).

    Args:
        result: the campaign.
        figures: figure name → PNG, in the order to show them (None: no figures section).
        files: the written files by role, for the files section (with ``out_dir``).
        out_dir: where the files are, for relative paths.
    """
    n = len(result.iterations)
    status = (
        f"converged after {n} iteration{'s' if n > 1 else ''}"
        if result.converged
        else f"**did not converge** within {n} iterations (the last factors are reported)"
    )
    summary = (
        f"Seed 000 Figure 7 on the {'digital twin' if result.truth is not None else 'robot'}: "
        f"rotation procedure first, then the longitudinal and lateral procedures, iterated "
        f"until no factor changes by more than {_tolerance_text(result)}; {status}. "
        f"Estimation: `{result.method}`; seed {result.seed}; "
        f"{result.robot_time_s / 60.0:.1f} min of robot time; "
        f"{result.wall_time_s:.1f} s of wall time for the runs and the analysis."
    )
    sections = [
        Section(
            "Correction factors (seed 000 Table 2)",
            (
                summary,
                (
                    "Sign conventions of docs/CONVENTIONS.md: a scaling k > 1 means the robot "
                    "falls short of its odometry; a cross-talk is the real yaw per metre, "
                    "counter-clockwise positive (seed 000 gives magnitudes only)."
                ),
                factors_table(result.factors, result.sigma, result.truth),
            ),
        )
    ]
    if result.measures_before is not None and result.measures_after is not None:
        sections.append(
            Section(
                "Before and after calibration (seed 000 §3.2)",
                (
                    (
                        "The same measurement scripts run uncalibrated and calibrated on the "
                        "twin, measured against its ground truth (used for measuring only, never "
                        "for estimating): 3 turns in place; 10 m of odometry travel as four 2.5 m "
                        "legs forward/reverse; the same left/right (lateral drift: how far each "
                        "leg really ends off its line, summed); cross-talk from the real heading "
                        "change per real metre of each leg."
                    ),
                    measures_table(result.measures_before, result.measures_after),
                    crosstalk_table(result.measures_before, result.measures_after),
                ),
            )
        )
    sections.append(
        Section(
            "Iterations",
            (
                (
                    "Totals of each iteration (installed for the next), change from the factors "
                    "installed at its start in brackets. Cross-talks in rad/m."
                ),
                iterations_table(result.iterations),
            ),
        )
    )
    if result.validation is not None:
        sections.append(
            Section(
                "Validation",
                (
                    (
                        "The three procedures once more with the final factors installed; what "
                        "they still measure (the residual) should be zero within its uncertainty."
                    ),
                    validation_table(result.validation),
                ),
            )
        )
    notes = [
        f"iteration {it.index} {stage}: {note}"
        for it in result.iterations
        for stage, est in (("rotation", it.rotation), ("translation", it.translation))
        for note in est.notes
    ]
    if result.validation is not None:
        notes += [f"validation: {note}" for note in result.validation.estimate.notes]
    if notes:
        sections.append(Section("Notes", ("\n".join(f"- {note}" for note in notes),)))
    if figures:
        blocks: list[Block] = [
            (
                "Black: odometry (of the hedgehog, initialised from the IPS at the first "
                "stand-still and turned along the first move, as seed 000 does); blue points: IPS "
                "positions (omnical's robust multilateration of the raw distances); red: the arcs "
                "fitted to each translation, numbered in the order of travel; orange circles: "
                "stand-still averages; light red square and blue circle: final positions by "
                "odometry and by the IPS. Grid 0.5 m. Under the title and framed beside the "
                "map: the factors the run measured (± 1σ, with the change from those installed); "
                "for a validation run, what is left (the residual)."
            )
        ]
        blocks += [FigureLink(path, f"{name} — {_caption(name)}") for name, path in figures.items()]
        sections.append(Section("Figures", tuple(blocks)))
    if files and out_dir is not None:
        sections.append(_files_section(result, files, out_dir))
    return sections


def _files_section(result: CampaignResult, files: Mapping[str, Path], out: Path) -> Section:
    roles = {
        "factors": "the factors with one-sigma uncertainties",
        "header": "C header for the vehicle-controller firmware",
        "ros_params": "ROS 2 parameters for the Wheeltec driver node",
    }
    items = [f"- `{_relative(files[r], out)}`: {text}" for r, text in roles.items() if r in files]
    bags = {k.removeprefix("recording:"): p for k, p in files.items() if k.startswith("recording:")}
    blocks: list[Block] = []
    if bags:
        items.append(
            "- `recordings/`: the procedure and validation runs (ROS 2 bags, MCAP); "
            "each carries the factors it ran with on `/omnical/events`"
        )
    blocks.append("\n".join(items))
    if bags:
        chosen = [p for name, p in bags.items() if name.startswith("validation-")] or list(
            bags.values()
        )
        args = " ".join(_relative(p, out) for p in chosen)
        blocks += [
            "Re-run the analysis offline, for example on the validation runs:",
            (
                "```sh\n"
                f"omnical calibrate estimate {args} --robot {result.robot_name} "
                "--out revalidated/factors.yaml\n```"
            ),
        ]
    return Section("Files", tuple(blocks))


_PROCEDURE_FACTORS: Mapping[str, tuple[Factor, ...]] = {
    "rotation": (Factor.SCALE_ROTATIONAL,),
    "longitudinal": (
        Factor.SCALE_LONGITUDINAL,
        Factor.CROSSTALK_FORWARD,
        Factor.CROSSTALK_REVERSE,
    ),
    "lateral": (Factor.SCALE_LATERAL, Factor.CROSSTALK_LEFT, Factor.CROSSTALK_RIGHT),
}
"""The factors each procedure measures (seed 000 §3.2.1–3.2.3)."""

_JOINT_NOTE = {
    "longitudinal": "(one estimate with the lateral run)",
    "lateral": "(one estimate with the longitudinal run)",
}


def _with_sigma(factor: Factor, value: float, sigma: float) -> str:
    """A factor ``± 1σ``: a scaling as it is, a cross-talk in mrad/m."""
    if factor.is_scale:
        text, s, unit = f"{value:.5f}", f"{sigma:.5f}", ""
    else:
        text, s, unit = f"{1e3 * value:+.2f}", f"{1e3 * sigma:.2f}", " mrad/m"
    return f"{text} ± {s}{unit}" if math.isfinite(sigma) else f"{text}{unit} (σ unknown)"


def _residual_with_sigma(factor: Factor, value: float, sigma: float, installed: float) -> str:
    """A residual ``± 1σ``: of a scaling in % (from 1), of a cross-talk in mrad/m."""
    if not factor.is_scale:
        return _with_sigma(factor, value, sigma)
    text = f"{100.0 * (value - 1.0):+.3f}"
    s = 100.0 * sigma / installed
    return f"{text} ± {s:.3f} %" if math.isfinite(s) else f"{text} % (σ unknown)"


def _change(factor: Factor, installed: float, value: float) -> str:
    change = factor.change(installed, value)
    was = f"{installed:.5f}" if factor.is_scale else f"{1e3 * installed:+.2f} mrad/m"
    moved = f"{100.0 * change:+.3f} %" if factor.is_scale else f"{1e3 * change:+.2f} mrad/m"
    return f"(installed {was}: {moved})"


def procedure_measured(result: CampaignResult, name: str) -> tuple[str, tuple[str, ...]]:
    """What the procedure run ``name`` (``iter1-rotation`` … ``validation-lateral``) measured:
    a line for its figure's title and the lines framed beside its map (empty if unknown)."""
    stage, _, kind = name.partition("-")
    factors = _PROCEDURE_FACTORS.get(kind, ())
    iteration = next((it for it in result.iterations if f"iter{it.index}" == stage), None)
    if iteration is not None:
        est = iteration.rotation if kind == "rotation" else iteration.translation
        head, title = "measured (totals to install, ± 1σ):", "measured"
    elif stage == "validation" and result.validation is not None:
        est = result.validation.estimate
        head = "still measured with the final factors\ninstalled (0 within σ when right):"
        title = "residual"
    else:
        return "", ()
    parts, lines = [], [*head.split("\n"), ""]
    for f in factors:
        if f.field in est.held:
            parts.append(f"{f.short} not estimated")
            lines.append(f"{f.short:<7} not estimated: {est.held[f.field]}")
            continue
        value, sigma = getattr(est.factors, f.field), est.sigma[f.field]
        installed = getattr(est.installed, f.field)
        if iteration is not None:
            shown = _with_sigma(f, value, sigma)
            lines += [f"{f.short:<7} {shown}", f"{'':<7} {_change(f, installed, value)}"]
        else:
            residual = getattr(est.residual, f.field)
            shown = _residual_with_sigma(f, residual, sigma, installed)
            z = result.validation.z_scores()[f.field] if result.validation else math.nan
            lines.append(f"{f.short:<7} {shown}" + (f"  ({z:+.1f} σ)" if math.isfinite(z) else ""))
        parts.append(f"{f.short} {shown}")
    note = (
        _JOINT_NOTE.get(kind)
        if iteration is not None
        else "(one estimate of the 3 validation runs)"
    )
    if note:
        lines += ["", note]
    return f"{title}: " + ", ".join(parts), tuple(lines)


def _figure_order(names: list[str]) -> list[str]:
    known = [n for n in _FIGURE_CAPTIONS if n in names]
    return known + sorted(n for n in names if n not in _FIGURE_CAPTIONS)


def _draw_figures(
    result: CampaignResult,
    robot: RobotDescription,
    beacons: BeaconMap | None,
    folder: Path,
    say: Say,
) -> dict[str, Path]:
    from omnical.reports.figures.calibration import plot_measures, plot_procedure

    drawn: dict[str, Path] = {}
    offset = hedge_offset_xy(robot.hedge_offset_m)
    for name, rec in result.procedure_runs.items():
        say(f"drawing figures/{name}.png")
        tracks = procedure_tracks(
            rec,
            beacons=beacons,
            odom_yaw_deadband_radps=yaw_deadband_radps(robot.odom_yaw_resolution_radps),
        )
        arcs, _ = move_arcs(tracks, hedge_offset_xy_m=offset)
        stage, kind = name.split("-", 1)
        when = (
            "validation (final factors installed)"
            if stage == "validation"
            else f"iteration {stage.removeprefix('iter')}"
        )
        summary, measured = procedure_measured(result, name)
        title = f"{result.robot_name}: {kind} procedure, {when}"
        drawn[name] = plot_procedure(
            tracks,
            arcs,
            folder / f"{name}.png",
            beacons=beacon_map_of(rec, beacons),
            hedge_offset_xy_m=offset,
            title=f"{title}\n{summary}" if summary else title,
            measured=measured,
        )
    if result.measures_before is not None and result.measures_after is not None:
        say("drawing figures/measures.png")
        drawn["measures"] = plot_measures(
            result.measures_before,
            result.measures_after,
            MEASURE_SPECS,
            folder / "measures.png",
            title=f"{result.robot_name}: seed 000 §3.2 measures before and after calibration",
        )
    return {name: drawn[name] for name in _figure_order(list(drawn))}


def write_campaign(
    result: CampaignResult,
    out_dir: str | Path,
    robot: RobotDescription,
    *,
    beacons: BeaconMap | None = None,
    figures: bool = True,
    save_recordings: bool = True,
    on_progress: Say | None = None,
    overwrite: bool = False,
    notify: Notify | None = None,
) -> CampaignFiles:
    """Write the campaign's files under ``out_dir`` (docs/DESIGN-NOTES.md), swapped in whole.

    Args:
        result: the campaign.
        out_dir: the directory (created if needed).
        robot: the robot description (the hedgehog offset, for the figures).
        beacons: the beacon map the campaign used (None: each recording's own).
        figures: draw the figures.
        save_recordings: write the procedure and validation bags.
        on_progress: receives one line per file.
        overwrite: replace an earlier omnical output in ``out_dir``
            (:func:`omnical.reports.outputs.claim_directory`).
        notify: told where an unfinished output was kept (``OUT.partial``).

    Raises:
        OutputError: ``out_dir`` is a file, holds someone else's files, or an earlier output
            without ``overwrite``.
        RecordingError: a file cannot be written.
    """
    t_start = time.perf_counter()
    say = on_progress or (lambda _line: None)
    claimed = claim_directory(
        out_dir, overwrite=overwrite, writer="omnical calibrate campaign", notify=notify
    )
    with claimed.staged(notify) as out:
        files = _write_files(result, out, robot, beacons, figures, save_recordings, say)
    report = files["report"]
    written = CampaignFiles(out, report, files, time.perf_counter() - t_start)
    return written.moved(claimed.final)


def _write_files(
    result: CampaignResult,
    out: Path,
    robot: RobotDescription,
    beacons: BeaconMap | None,
    figures: bool,
    save_recordings: bool,
    say: Say,
) -> dict[str, Path]:
    """Write the campaign's files in ``out``; every file by role (:class:`CampaignFiles`)."""
    files: dict[str, Path] = {}
    unc = result.uncertainty()
    say("writing factors.yaml, omnical_factors.h, wheeltec_params.yaml")
    comment = (
        f"omnical calibrate campaign: {result.robot_name}, {len(result.iterations)} "
        f"iteration(s), method {result.method}, seed {result.seed}"
    )
    files["factors"] = write_factors(out / "factors.yaml", result.factors, unc, comment=comment)
    files["header"] = write_c_header(out / "omnical_factors.h", result.factors, unc)
    files["ros_params"] = write_wheeltec_params(out / "wheeltec_params.yaml", result.factors, unc)
    if save_recordings:
        for name, rec in result.procedure_runs.items():
            say(f"writing recordings/{name}.mcap")
            files[f"recording:{name}"] = write_bag(rec, out / "recordings" / f"{name}.mcap")
    drawn = _draw_figures(result, robot, beacons, out / "figures", say) if figures else {}
    files.update({f"figure:{name}": path for name, path in drawn.items()})
    say("writing report.md")
    files["report"] = write_markdown_report(
        out,
        f"Calibration report — {result.robot_name}",
        campaign_sections(result, drawn, files, out),
    )
    return files

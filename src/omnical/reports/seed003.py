"""Seed 003's chapter: the tuned motor loop, Table II, the four tests beside the paper's errors.

:func:`seed003_sections` (figures, sections for any report), :func:`write_seed003` (``--out DIR``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from omnical.control.pid import PidParams
from omnical.control.ziegler_nichols import ZnRule, step_response_metrics, ziegler_nichols_gains
from omnical.paper import SEED003_PAPER_TABLE2, SEED003_PAPER_TEST_ERRORS
from omnical.reports.figures.seed003 import plot_seed003_step_responses, plot_seed003_test
from omnical.reports.markdown import (
    Block,
    FigureLink,
    MarkdownTable,
    Section,
    write_markdown_report,
)
from omnical.reports.outputs import Notify, claim_directory
from omnical.services.seed003 import ERROR_LABELS, Seed003Result
from omnical.twin.motor import RPM_PER_RADPS, RuleComparison, wheel_speed_loop

__all__ = ["Seed003Files", "seed003_sections", "write_seed003"]


@dataclass(frozen=True)
class Seed003Files:
    """What :func:`write_seed003` wrote: ``report.md`` and its figures."""

    report: Path
    figures: tuple[Path, ...]


def _overshoot_of(result: Seed003Result, pid: PidParams, setpoint_rpm: float = 100.0) -> float:
    """Overshoot of the noise-free step without output limit (as the table's column)."""
    dtr = result.robot.drive_train
    motor = result.params.wheel_motors(dtr, result.robot.wheel_count)[0]
    r = setpoint_rpm / RPM_PER_RADPS
    t, y = wheel_speed_loop(dtr, pid, r, 1.0, quantize=False, motor=motor)
    return step_response_metrics(t, y, r).overshoot


def _no_overshoot_note(result: Seed003Result) -> str | None:
    """Why the "no overshoot" row overshoots, measured on the same loop; None when it does not.

    The rule keeps the classic Ti = Pu/2 and only lowers Kp. Here Pu comes from the one-period
    delay of the speed reading, not from the motor's lag, so Ti is far shorter than the lag
    and the overshoot is the integral's: the same gains are stepped without the integral, with
    a four times longer Ti, and with Kp raised to the some-overshoot row's.
    """
    by_rule: dict[ZnRule, RuleComparison] = {c.rule: c for c in result.tuning.comparisons}
    no, some = by_rule.get(ZnRule.PID_NO_OVERSHOOT), by_rule.get(ZnRule.PID_SOME_OVERSHOOT)
    if no is None or no.metrics.overshoot <= result.tuning.max_overshoot:
        return None
    u = result.tuning.ultimate
    gains = ziegler_nichols_gains(u.ku, u.pu_s, ZnRule.PID_NO_OVERSHOOT)
    tau_s = result.params.wheel_motors(result.robot.drive_train, result.robot.wheel_count)[
        0
    ].time_constant_s
    without_i = _overshoot_of(result, replace(gains, ti_s=math.inf))
    slower_i = _overshoot_of(result, replace(gains, ti_s=4.0 * gains.ti_s))
    kp_factors = (0.1, 0.2, 1.0 / 3.0, 0.45)
    over_kp = [_overshoot_of(result, replace(gains, kp=f * u.ku)) for f in kp_factors]
    beside = (
        f", more than the some-overshoot row ({some.metrics.overshoot:.0%})"
        if some is not None and some.metrics.overshoot < no.metrics.overshoot
        else ""
    )
    tl = by_rule.get(ZnRule.TYREUS_LUYBEN)
    tyreus = (
        f" Tyreus–Luyben's Ti = 2.2 Pu ({tl.pid.ti_s * 1e3:.0f} ms, near τ) is why its row "
        f"overshoots {tl.metrics.overshoot:.0%}."
        if tl is not None
        else ""
    )
    return (
        f'**Why "no overshoot" overshoots {no.metrics.overshoot:.0%}{beside}** (measured on '
        "the same noise-free loop): the rule only lowers Kp, to 0.2 Ku, and keeps the classic "
        f"Ti = Pu/2 = {gains.ti_s * 1e3:.1f} ms. On this motor Pu ({u.pu_s * 1e3:.1f} ms) is set "
        "by the one-period delay of the speed reading, not by the motor's lag "
        f"(τ = {tau_s * 1e3:.0f} ms), so the integral acts about {tau_s / gains.ti_s:.0f}× "
        "faster than the motor responds, and the overshoot is the integral's: the same gains "
        f"without the integral (PD) overshoot {without_i:.0%}, with Ti four times longer "
        f"{slower_i:.0%}. Lowering Kp does not help while Ti and Td are held (the no- and "
        "some-overshoot rows share Ti = Pu/2 and Td = Pu/3): from 0.1 Ku to 0.45 Ku the "
        f"overshoot stays within {min(over_kp):.0%}–{max(over_kp):.0%}. The drive limit is not the "
        f"cause: limited, the same step overshoots less ({no.metrics_limited.overshoot:.0%})."
        f"{tyreus}"
    )


def _tuning_section(result: Seed003Result, fig_dir: Path) -> tuple[Section, Path]:
    tuning = result.tuning
    u = tuning.ultimate
    fig = plot_seed003_step_responses(
        fig_dir / "seed003-fig5-step-response.png", tuning.comparisons, chosen=tuning.chosen
    )
    rows = tuple(
        (
            c.rule.value + (" (installed)" if c is tuning.chosen else ""),
            f"{c.pid.kp:.3f}",
            f"{c.pid.ti_s * 1e3:.2f}",
            f"{c.pid.td_s * 1e3:.2f}",
            f"{c.metrics.overshoot:.0%}",
            f"{c.metrics.settling_time_s * 1e3:.0f}",
            f"{c.metrics_limited.overshoot:.0%}",
            f"{c.metrics_limited.settling_time_s * 1e3:.0f}",
        )
        for c in tuning.comparisons
    )
    table = MarkdownTable(
        (
            "rule",
            "Kp",
            "Ti (ms)",
            "Td (ms)",
            "overshoot",
            "settling 2 % (ms)",
            "overshoot, drive limited",
            "settling, drive limited (ms)",
        ),
        rows,
        caption="Wheel-speed PID of the omni-X twin (seed 003 §IV.A)",
        note=(
            "Overshoot and settling of the noise-free 100 rpm step: without output limit (the "
            "small-signal behaviour, which decides) and from rest with the firmware's drive "
            "limit (the large step saturates, hiding part of the overshoot). Seed 003: Kp = 5, "
            "Ti = 2.8, Td = 0.6, in units it does not state (its Kp acts on rpm, ours is "
            "rad/s of drive per rad/s of error)."
        ),
    )
    why = (
        f"The refinement is installed: the classic row overshoots "
        f"{tuning.classic.metrics.overshoot:.0%} (> {tuning.max_overshoot:.0%})."
        if tuning.refined
        else "The classic row is installed."
    )
    text = (
        f"Ziegler–Nichols 2 (closed loop, ultimate gain) on the twin's first motor at 100 rpm: "
        f"P-only loop, gain bisected between decaying and growing oscillation "
        f"({u.experiments} experiments): **Ku = {u.ku:.3f}, Pu = {u.pu_s * 1e3:.1f} ms** (the loop "
        f"oscillates through the one-period delay of the encoder speed, 100 Hz). Classic PID "
        f"row: Kp = 0.6 Ku, Ti = Pu/2, Td = Pu/8. {why} The installed gains run all four wheel "
        f"loops of the twin's firmware in every test below."
    )
    note = _no_overshoot_note(result)
    blocks: tuple[Block, ...] = (text, table, *((note,) if note else ()))
    return Section(
        "Seed 003: motor speed control", (*blocks, FigureLink(fig, "Fig. 5 on the twin"))
    ), fig


def _table2(result: Seed003Result) -> MarkdownTable:
    sp, ours = result.table2_setpoints_rpm, result.table2_means_rpm
    paper = np.array(SEED003_PAPER_TABLE2)
    rows = tuple(
        (f"{s:g}", *(f"{v:.1f}" for v in ours[i]), *(f"{v:.1f}" for v in paper[i]))
        for i, s in enumerate(sp)
    )
    err_ours = np.abs(ours - sp[:, None])
    err_paper = np.abs(paper - sp[:, None])
    note = (
        f"Largest |error|: twin {err_ours.max():.2f} rpm (RMS {np.sqrt(np.mean(err_ours**2)):.2f}), "
        f"paper {err_paper.max():.2f} rpm (RMS {np.sqrt(np.mean(err_paper**2)):.2f}). Each cell: "
        "100 readings after 1 s, mean of 10 runs, as the paper measured; the twin's motors have "
        "their gain, lag and friction errors, a 50 µs timing jitter of each speed reading and a "
        "5 % load ripple once per wheel turn."
    )
    header = (
        "set point (rpm)",
        *(f"twin M{j + 1}" for j in range(ours.shape[1])),
        *(f"paper M{j + 1}" for j in range(paper.shape[1])),
    )
    return MarkdownTable(header, rows, caption="Table II: mean motor speed (rpm)", note=note)


def _tests_section(result: Seed003Result, fig_dir: Path) -> tuple[Section, list[Path]]:
    blocks: list[Block] = []
    rows = []
    figures = []
    for test in result.tests:
        labels = ERROR_LABELS[test.slug]
        paper = SEED003_PAPER_TEST_ERRORS[test.slug]
        est, gt = test.estimate_errors, test.truth_errors
        for label, p, e, g in zip(
            labels, paper, (est.first, est.second), (gt.first, gt.second), strict=True
        ):
            rows.append((test.name, label, f"{p:g}", f"{e:.2f}", f"{g:.2f}"))
        fig = plot_seed003_test(
            fig_dir / f"seed003-{test.slug}.png",
            reference_m=test.reference_m,
            estimate=test.estimate_path,
            truth=test.truth_path,
            title=f"omni-X twin: {test.name}",
        )
        figures.append(fig)
    table = MarkdownTable(
        ("test", "measure", "paper", "twin: estimate", "twin: ground truth"),
        tuple(rows),
        caption="Seed 003's four tests on the omni-X twin, closed on the seed 003 estimate",
        note=(
            "'estimate' is what the paper could measure (its own odometry against the set "
            "point); 'ground truth' is the twin's true pose, which the paper could not measure. "
            "The trajectories are driven straight from corner to corner with the heading held "
            "(the triangle's second leg is the diagonal to (60, 60) cm, Fig. 9); deviations are "
            "from the nearest point of the leg being driven (the controller's current goal). "
            "The loop closes on the estimate, so the estimate's errors are the controller's "
            "own: a goal counts as reached within 1 cm, and the next leg starts from there. "
            "`omnical run seed003-square --model omni-x` runs one test alone and records it."
        ),
    )
    text = (
        "The loop closes on seed 003's own odometry: three dead-wheel encoders (true radii "
        "off by 0.2–0.4 %, 1 % slip), the encoder heading blended 0.5/0.5 with the IMU yaw "
        "(gyro with bias, pulled to the tilt-compensated magnetometer yaw), Eq. 6–19. "
        "Position loops: P on each body axis, PI on the heading (seed 003 gives no values)."
    )
    blocks += [text, table]
    blocks += [FigureLink(f, t.name) for f, t in zip(figures, result.tests, strict=True)]
    return Section("Seed 003: positioning tests", tuple(blocks)), figures


def seed003_sections(
    result: Seed003Result, fig_dir: str | Path
) -> tuple[list[Section], list[Path]]:
    """Draw the figures into ``fig_dir``; the sections (tuning + Table II, tests) and figures."""
    fdir = Path(fig_dir)
    tuning, fig5 = _tuning_section(result, fdir)
    tuning = Section(tuning.heading, (*tuning.blocks, _table2(result)))
    tests, figs = _tests_section(result, fdir)
    return [tuning, tests], [fig5, *figs]


def write_seed003(
    result: Seed003Result,
    out_dir: str | Path,
    *,
    overwrite: bool = False,
    notify: Notify | None = None,
) -> Seed003Files:
    """Write ``out_dir/report.md`` and ``out_dir/figures/`` (the directory claimed first, then
    swapped in whole; ``notify``: told where an unfinished one was kept)."""
    claimed = claim_directory(out_dir, overwrite=overwrite, writer="omnical seed003", notify=notify)
    with claimed.staged(notify) as out:
        sections, figures = seed003_sections(result, out / "figures")
        report = write_markdown_report(
            out, f"Seed 003 on the omni-X twin (seed {result.seed})", sections
        )
    return Seed003Files(claimed.final(report), tuple(map(claimed.final, figures)))

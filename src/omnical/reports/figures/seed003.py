"""Seed 003's figures on the omni-X twin: the motor step response (Fig. 5) and the tests (Figs. 6–9)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import ArrayLike

from omnical.reports.figures._common import finish_plan_view, save_figure
from omnical.twin.motor import RuleComparison

__all__ = ["plot_seed003_step_responses", "plot_seed003_test"]


def plot_seed003_step_responses(
    path: Path,
    comparisons: tuple[RuleComparison, ...],
    *,
    chosen: RuleComparison,
    setpoint_rpm: float = 100.0,
) -> Path:
    """Measured wheel speed after a 100 rpm step for each tuning rule (seed 003 Fig. 5)."""
    fig, ax = plt.subplots(figsize=(8, 4.8))
    for c in comparisons:
        installed = c is chosen
        label = (
            f"{c.rule.value}: Kp {c.pid.kp:.2f}, Ti {c.pid.ti_s * 1e3:.1f} ms, "
            f"Td {c.pid.td_s * 1e3:.1f} ms; overshoot {c.metrics_limited.overshoot:.0%} here, "
            f"{c.metrics.overshoot:.0%} small-signal" + (" (installed)" if installed else "")
        )
        ax.plot(c.t_s * 1e3, c.speed_rpm, "-", lw=2.0 if installed else 0.9, label=label, alpha=0.9)
    ax.axhline(
        setpoint_rpm, color="black", ls="--", lw=0.8, label=f"set point {setpoint_rpm:g} rpm"
    )
    ax.set_xlim(0, 400)
    ax.set_xlabel("time (ms)")
    ax.set_ylabel("measured wheel speed (rpm)")
    ax.set_title(
        "omni-X twin, one motor: 100 rpm step with each rule's gains (seed 003 Fig. 5)\n"
        "as the firmware measures it (quantised encoder, reading jitter, load ripple, drive limit);\n"
        "overshoot 'here': this step from rest, drive-limited; 'small-signal': without the limit "
        "(what decides the rule)",
        fontsize=9,
    )
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower right", framealpha=0.9)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_seed003_test(
    path: Path,
    *,
    reference_m: ArrayLike,
    estimate: ArrayLike,
    truth: ArrayLike,
    title: str,
) -> Path:
    """Reference (red), seed 003 estimate closing the loop (black), ground truth (blue), in cm."""
    ref = np.asarray(reference_m, dtype=np.float64) * 100
    est = np.asarray(estimate, dtype=np.float64)
    gt = np.asarray(truth, dtype=np.float64)
    fig, ax = plt.subplots(figsize=(6.5, 6))
    ax.plot(ref[:, 0], ref[:, 1], "--o", color="tab:red", lw=1.2, ms=4, label="reference")
    ax.plot(
        est[:, 1] * 100,
        est[:, 2] * 100,
        "-",
        color="black",
        lw=1.0,
        label="seed 003 estimate (closes the loop)",
    )
    ax.plot(gt[:, 1] * 100, gt[:, 2] * 100, "-", color="tab:blue", lw=1.0, label="ground truth")
    ax.plot(est[-1, 1] * 100, est[-1, 2] * 100, "s", color="black", ms=6, mfc="white")
    ax.plot(gt[-1, 1] * 100, gt[-1, 2] * 100, "o", color="tab:blue", ms=7, mfc="white")
    finish_plan_view(ax, title=title, xlabel="x (cm)", ylabel="y (cm)")
    return save_figure(fig, path)

"""Seed 003 end to end on the omni-X twin: the service, its report, the command."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omnical.control.ziegler_nichols import ZnRule
from omnical.reports.seed003 import write_seed003
from omnical.services.seed003 import run_seed003
from omnical.twin.params import OMNI_X_WHEEL_PID


def test_seed003_story(tmp_path: Path) -> None:
    result = run_seed003(seed=0)
    tuning = result.tuning
    # the classic row overshoots, the Tyreus–Luyben refinement is installed, and it is the
    # omni-x twin's default wheel PID
    assert tuning.classic.metrics.overshoot > 0.5
    assert tuning.chosen.rule == ZnRule.TYREUS_LUYBEN
    assert tuning.chosen.metrics.overshoot < 0.25
    assert result.params.wheel_pid is tuning.chosen.pid
    for name in ("kp", "ti_s", "td_s"):
        assert getattr(tuning.chosen.pid, name) == getattr(OMNI_X_WHEEL_PID, name)
    # Table II of the paper's order: within 1 rpm, not within 0.01
    err = np.abs(result.table2_means_rpm - result.table2_setpoints_rpm[:, None])
    assert 0.1 < err.max() < 1.0
    assert [t.slug for t in result.tests] == [
        "centred-turning",
        "driving-forward",
        "square",
        "triangle",
    ]
    for test in result.tests:
        assert test.run.control.reason == "done"
        assert test.run.pose_source == "seed003"
        assert max(test.truth_errors.first, test.truth_errors.second) < 10.0
    files = write_seed003(result, tmp_path / "out")
    text = files.report.read_text(encoding="utf-8")
    assert "Table II" in text and "ground truth" in text
    # the no-overshoot row overshoots more than the some-overshoot row: explained, measured
    by_rule = {c.rule: c for c in tuning.comparisons}
    no = by_rule[ZnRule.PID_NO_OVERSHOOT].metrics.overshoot
    assert no > by_rule[ZnRule.PID_SOME_OVERSHOOT].metrics.overshoot
    assert f'Why "no overshoot" overshoots {no:.0%}' in text
    assert "without the integral (PD) overshoot 0%" in text
    assert len(files.figures) == 5
    assert all(f.is_file() for f in files.figures)

"""The demo end to end (issue 5): before/after Lissajous, campaign, closed-loop paths, report."""

from __future__ import annotations

from pathlib import Path

import pytest

from omnical.demo import run_demo


@pytest.mark.slow
def test_demo_calibrated_lissajous_is_at_least_7x_better(tmp_path: Path) -> None:
    result = run_demo(tmp_path, seed=0)
    # issue 5: the calibrated open-loop Lissajous has a ground-truth RMSE ≥ 7× lower
    assert result.improvement >= 7.0
    assert result.before["ground_truth"].rmse_m > 0.03
    # odometry follows the open-loop commands either way (it is what they integrate to)
    assert result.before["odometry"].rmse_m < 0.01
    assert result.after["multilateration"].rmse_m < result.before["multilateration"].rmse_m
    for path in result.paths:
        assert path.final_vs_odometry_m < 0.03
        assert path.final_vs_ground_truth_m < 0.05
        assert path.figure.is_file()
    text = result.report_path.read_text()
    assert "seed 000 Table 4" in text
    assert "Ziegler–Nichols" in text
    for line in text.splitlines():
        if line.startswith("!["):
            assert (tmp_path / line.split("(")[1].rstrip(")")).is_file()
    assert (tmp_path / "calibration" / "report.md").is_file()
    assert (tmp_path / "calibration" / "factors.yaml").is_file()

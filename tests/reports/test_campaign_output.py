"""What ``omnical calibrate campaign`` prints last: the whole command's wall time, labelled.

The campaign's own wall time (:attr:`CampaignResult.wall_time_s`) leaves out writing the bags,
report and figures, which took most of a 33.8 s command that printed "wall time 6.5 s".
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from omnical.cli.calibrate_output import print_campaign
from omnical.kinematics.correction import CorrectionFactors


def _result() -> SimpleNamespace:
    return SimpleNamespace(
        robot_name="rosy-mecanum",
        factors=CorrectionFactors(),
        sigma={},
        truth=None,
        iterations=(object(),),
        converged=True,
        measures_before=None,
        measures_after=None,
        robot_time_s=120.0,
        wall_time_s=6.5,
    )


def test_the_command_time_is_printed_with_its_parts(capsys: pytest.CaptureFixture[str]) -> None:
    print_campaign(_result(), ["wrote calib/report.md"], command_wall_s=33.8)  # type: ignore[arg-type]
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last == (
        "robot time 2.0 min, wall time 33.8 s (the campaign 6.5 s, writing the files 27.3 s)"
    )


def test_without_the_command_time_the_campaign_time_says_what_it_is(
    capsys: pytest.CaptureFixture[str],
) -> None:
    print_campaign(_result(), [])  # type: ignore[arg-type]
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last == "robot time 2.0 min, wall time 6.5 s (the campaign)"

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from omnical.cli.main import app

WORLDS = Path(__file__).parents[2].parent / "shared" / "worlds"


def _lab() -> Path:
    path = WORLDS / "lab-8x6.yaml"
    if not path.is_file():
        pytest.skip(f"{path} not available")
    return path


def test_plan_writes_csv(tmp_path: Path) -> None:
    out = tmp_path / "path.csv"
    res = CliRunner().invoke(
        app, ["plan", str(_lab()), "--from", "1,1", "--to", "6.5,1.0", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert out.read_text().startswith("x_m,y_m\n")
    np.testing.assert_allclose(rows[0], [1, 1])
    np.testing.assert_allclose(rows[-1], [6.5, 1.0])


def test_plan_reports_collision_and_bad_input(tmp_path: Path) -> None:
    out = tmp_path / "p.csv"
    res = CliRunner().invoke(
        app, ["plan", str(_lab()), "--from", "0.05,0.05", "--to", "6.5,1", "--out", str(out)]
    )
    assert res.exit_code == 1 and "start_in_collision" in res.output
    res = CliRunner().invoke(
        app, ["plan", str(_lab()), "--from", "1;1", "--to", "6.5,1", "--out", str(out)]
    )
    assert res.exit_code == 2 and "--from" in res.output

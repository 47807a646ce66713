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
    assert res.exit_code == 3 and "start_in_collision" in res.output  # ran; no usable result
    res = CliRunner().invoke(
        app, ["plan", str(_lab()), "--from", "1;1", "--to", "6.5,1", "--out", str(out)]
    )
    assert res.exit_code == 2 and "--from" in res.output


def test_simulate_with_world_then_map(tmp_path: Path) -> None:
    script = tmp_path / "s.yaml"
    script.write_text(
        "name: short\nsteps:\n"
        "  - move: {vx_mps: 0.25, distance_m: 1.5}\n"
        "  - move: {wz_radps: 0.5, angle_deg: 90}\n"
        "  - move: {vx_mps: 0.25, distance_m: 1.0}\n",
        encoding="utf-8",
    )
    bag = tmp_path / "run.mcap"
    res = CliRunner().invoke(
        app, ["simulate", str(script), "--world", str(_lab()), "--out", str(bag)]
    )
    assert res.exit_code == 0, res.output
    out = tmp_path / "maps" / "lab.yaml"
    res = CliRunner().invoke(
        app, ["map", str(bag), "--initial-pose", "1.5,1.2,0", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    assert "against /ground_truth" in res.output
    text = out.read_text()
    assert "occupied_thresh: 0.65" in text and "free_thresh: 0.196" in text
    assert "mode: trinary" in text
    assert (tmp_path / "maps" / "lab.pgm").read_bytes().startswith(b"P5")
    tum = np.loadtxt(tmp_path / "maps" / "lab.tum")
    assert tum.shape[1] == 8
    np.testing.assert_allclose(tum[0, 1:3], [1.5, 1.2], atol=1e-9)  # the map in the world frame
    assert (tmp_path / "maps" / "lab.png").read_bytes().startswith(b"\x89PNG")
    # again without --overwrite: refused before any work; with it: replaced
    res = CliRunner().invoke(app, ["map", str(bag), "--out", str(out)])
    assert res.exit_code == 2 and "--overwrite" in res.output
    res = CliRunner().invoke(app, ["map", str(bag), "--out", str(tmp_path / "m.pgm")])
    assert res.exit_code == 2 and "MAP.yaml" in res.output


def test_map_needs_scans(tmp_path: Path) -> None:
    bag = tmp_path / "plain.mcap"
    script = tmp_path / "s.yaml"
    script.write_text("name: s\nsteps:\n  - hold: {duration_s: 0.5}\n", encoding="utf-8")
    assert CliRunner().invoke(app, ["simulate", str(script), "--out", str(bag)]).exit_code == 0
    res = CliRunner().invoke(app, ["map", str(bag), "--out", str(tmp_path / "m.yaml")])
    assert res.exit_code == 2 and "/scan" in res.output


def test_navigate_to_an_unreachable_goal_reports_the_plan_and_writes_nothing(
    tmp_path: Path,
) -> None:
    from importlib import resources

    lab = Path(str(resources.files("omnical").joinpath("data", "worlds", "lab-8x6.yaml")))
    out = tmp_path / "nav.mcap"
    args = ["navigate", "--world", str(lab), "--map", str(lab), "--start", "1,1,0"]
    result = CliRunner().invoke(app, [*args, "--goal", "4.0,0.05", "--out", str(out)])
    assert result.exit_code == 3, result.output
    assert "goal_in_collision" in result.output
    assert "no bag written" in result.output
    assert not (tmp_path / "nav").exists()


def test_a_point_outside_the_map_is_named_as_such(tmp_path: Path) -> None:
    args = [
        "plan",
        "lab-8x6",
        "--from",
        "1.5,1.2",
        "--to",
        "60,3",
        "--out",
        str(tmp_path / "p.csv"),
    ]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2
    assert "--to 60,3: outside the map" in res.output


def test_simulate_in_a_shipped_world_stops_at_a_collision(tmp_path: Path) -> None:
    """The built-in lab tour fits the lab; the beacon-room tour drives into its stub wall: the
    run stops there, is kept up to the collision, and the exit status says so."""
    from omnical.recording import read_bag
    from omnical.robot.loader import load_robot
    from omnical.services.navigation import robot_world

    fits = CliRunner().invoke(
        app, ["simulate", "lab-tour", "--world", "lab-8x6", "--out", str(tmp_path / "lab.mcap")]
    )
    assert fits.exit_code == 0, fits.output
    hits = CliRunner().invoke(
        app, ["simulate", "tour", "--world", "lab-8x6", "--out", str(tmp_path / "tour.mcap")]
    )
    assert hits.exit_code == 3, hits.output
    assert "collision: the footprint touches an occupied cell of lab-8x6" in hits.output
    assert "the run stops there" in hits.output
    kept = read_bag(tmp_path / "tour.mcap")
    assert 5.0 < kept.duration_s < 30.0  # up to the collision, not the tour's 82 s
    gt = kept.topic("/ground_truth")
    world = robot_world("lab-8x6", load_robot("rosy-mecanum"))
    poses = np.column_stack([gt["x_m"], gt["y_m"], gt["yaw_rad"]])
    assert world.first_collision(poses) == len(poses) - 1  # the last pose is the first hit
    assert kept.end_ns == int(gt.t_ns[-1])
    res = CliRunner().invoke(app, ["simulate", "tour", "--world", "lab-8x7", "--out", "x.mcap"])
    assert res.exit_code == 2 and "not a shipped world (lab-8x6, warehouse-20x20)" in res.output

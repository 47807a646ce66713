from __future__ import annotations

import os
import warnings
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
    assert "warning" not in res.output  # the start the bag's /ground_truth has
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
    # issue 29: a start the bag's /ground_truth contradicts was taken silently
    args = ["map", str(bag), "--out", str(tmp_path / "turned.yaml"), "--initial-pose"]
    res = CliRunner().invoke(app, [*args, "1.5,1.2,1.57"])
    text = " ".join(res.output.split())
    assert res.exit_code == 0, res.output
    assert "warning: --initial-pose 1.5,1.2,1.57 is 0.00 m and 90.0° from where the bag's" in text
    assert "--initial-pose 1.5,1.2,0 puts it there" in text


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
    from omnical.bags.bag import read_bag
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


def _refused_in_one_line(args: list[str]) -> str:
    """Run in-process, numpy's warnings as errors: exit 2 and one stderr line, returned."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = CliRunner().invoke(app, args)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "Warning" not in res.output
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("omnical: error: "), res.stderr
    return lines[0].removeprefix("omnical: error: ")


def _shipped_lab() -> Path:
    from omnical.navigation.map_io import resolve_world

    return resolve_world("lab-8x6")


_BAD_MAPS = {
    "resolution 1e300": ("resolution: 1.0e+300", "resolution: must be 0.001 to 10 m per cell"),
    "resolution 1e-300": ("resolution: 1.0e-300", "resolution: must be 0.001 to 10 m per cell"),
    "origin 1e300": ("origin: [1.0e+300, 0, 0]", "origin: x, y must lie within ±10000 m"),
    "image /dev/zero": ("image: /dev/zero", "image: /dev/zero is not a regular file"),
    "image FIFO": ("image: {tmp}/fifo", "image: {tmp}/fifo is not a regular file (a FIFO)"),
    "image directory": ("image: {tmp}", "image: {tmp} is a directory, not an image file"),
}


@pytest.mark.parametrize("as_", ["plan", "navigate --map", "navigate --world"])
@pytest.mark.parametrize("bad", sorted(_BAD_MAPS))
def test_a_map_out_of_any_map_is_one_line_without_warnings(
    tmp_path: Path, bad: str, as_: str
) -> None:
    """Tracebacks (resolution 1e300), RuntimeWarning lines (1e-300, origin 1e300) and "does
    not exist" for /dev/zero, a FIFO or a directory, before: now one line, exit 2."""
    lab = _shipped_lab()
    (tmp_path / "lab.pgm").write_bytes(lab.with_suffix(".pgm").read_bytes())
    os.mkfifo(tmp_path / "fifo")
    edit, reason = (part.replace("{tmp}", str(tmp_path)) for part in _BAD_MAPS[bad])
    key = edit.split(":")[0]
    lines = [edit if line.startswith(f"{key}:") else line for line in lab.read_text().splitlines()]
    lines = [line.replace("lab-8x6.pgm", "lab.pgm") for line in lines]
    bad_map = tmp_path / "bad.yaml"
    bad_map.write_text("\n".join(lines) + "\n")
    out = ["--out", str(tmp_path / "out.mcap")]
    legs = ["--start", "1.5,1.2,0", "--goal", "2.5,1.2", *out]
    args = {
        "plan": ["plan", str(bad_map), "--from", "1.5,1.2", "--to", "2.5,1.2", *out],
        "navigate --map": ["navigate", "--world", str(lab), "--map", str(bad_map), *legs],
        "navigate --world": ["navigate", "--world", str(bad_map), "--map", str(lab), *legs],
    }[as_]
    assert _refused_in_one_line(args).startswith(f"{bad_map}: {reason}")
    assert not list(tmp_path.glob("out*"))


_LEGS = ["--start", "1.5,1.2,0", "--goal", "2.5,1.2"]


@pytest.mark.parametrize("command", ["plan", "navigate"])
def test_a_negative_seed_is_a_usage_error_naming_it(tmp_path: Path, command: str) -> None:
    """--seed -1 ended in numpy's traceback; now the shared --seed option (≥ 0) of every
    command refuses it before any work."""
    out = ["--out", str(tmp_path / "out.mcap"), "--seed", "-1"]
    args = {
        "plan": ["plan", "lab-8x6", "--from", "1.5,1.2", "--to", "2.5,1.2", *out],
        "navigate": ["navigate", "--world", "lab-8x6", "--map", "lab-8x6", *_LEGS, *out],
    }[command]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "Warning" not in res.output
    (line,) = [line for line in res.stderr.splitlines() if "'--seed'" in line]
    assert "greater than or equal to 0" in line
    assert not list(tmp_path.glob("out*"))


@pytest.mark.parametrize(
    ("option", "value", "reason"),
    [
        ("--nodes", "100000000", "--nodes: must be 0 to 5000, got 100000000"),
        ("--nodes", "-1", "--nodes: must be 0 to 5000, got -1"),
        ("--connection-distance", "nan", "--connection-distance: must be > 0 m, got nan"),
        ("--connection-distance", "0", "--connection-distance: must be > 0 m, got 0.0"),
    ],
)
def test_plan_options_are_bounded(tmp_path: Path, option: str, value: str, reason: str) -> None:
    """--nodes 100000000 had no upper bound (it ran out of memory past a minute)."""
    out = tmp_path / "p.csv"
    args = ["plan", "lab-8x6", "--from", "1.5,1.2", "--to", "2.5,1.2", "--out", str(out)]
    assert _refused_in_one_line([*args, option, value]) == reason
    assert not out.exists()


def test_the_node_bound_is_the_planners() -> None:
    from omnical.cli.plan import MAX_NODES
    from omnical.errors import ConfigError
    from omnical.navigation.prm import MAX_NUM_NODES, PrmParams

    assert MAX_NODES == MAX_NUM_NODES
    assert PrmParams(MAX_NUM_NODES).num_nodes == MAX_NUM_NODES
    for bad in ({"num_nodes": MAX_NUM_NODES + 1}, {"seed": -1}):
        with pytest.raises(ConfigError):
            PrmParams(**bad)


@pytest.mark.parametrize(
    ("args", "reason"),
    [
        (["--start", "1.5,1.2,0", "--goal", "60,3"], "--goal 60,3: outside the map"),
        (["--start", "100,1.2,0", "--goal", "2.5,1.2"], "--start 100,1.2: outside the map"),
        (["--start", "1.5,1.2,0", "--goal", "1e308,0"], "--goal 1e+308,0: outside the map"),
    ],
)
def test_navigate_to_or_from_outside_the_map_is_a_mistake(
    tmp_path: Path, args: list[str], reason: str
) -> None:
    """Exit 3 (a plan's goal_in_collision) before; the README says a point outside the map
    is a mistake, exit 2, as in plan."""
    out = tmp_path / "nav.mcap"
    base = ["navigate", "--world", "lab-8x6", "--map", "lab-8x6", "--out", str(out)]
    assert _refused_in_one_line([*base, *args]) == f"{reason} lab-8x6"
    assert not list(tmp_path.iterdir())


def test_a_twin_starting_in_a_wall_is_a_mistake(tmp_path: Path) -> None:
    """Found by a new user: ``simulate --world`` with a start in the pillar ran (exit 3, a
    0-s bag written) and ``navigate --start`` there was a plan's start_in_collision (exit 3);
    the README says a twin starting in a wall is a mistake, exit 2, as ``ros2 twin`` has it."""
    pillar = "4.2,3.0,0"
    twin = tmp_path / "t.yaml"
    twin.write_text(f"base: default\nstart_pose_map: [{pillar}]\n", encoding="utf-8")
    out = ["--out", str(tmp_path / "run.mcap")]
    simulate = ["simulate", "lab-tour", "--world", "lab-8x6", "--twin", str(twin), *out]
    assert _refused_in_one_line(simulate) == (
        "the twin's start (4.2, 3) m puts the robot in a wall of lab-8x6 or outside it: give a "
        "free start_pose_map in the --twin file"
    )
    navigate = ["navigate", "--world", "lab-8x6", "--map", "lab-8x6", "--start", pillar]
    assert _refused_in_one_line([*navigate, "--goal", "2,2", *out]) == (
        "--start (4.2, 3) m puts the robot in a wall of lab-8x6 or outside it: give a free --start"
    )
    assert [p.name for p in tmp_path.iterdir()] == ["t.yaml"]


def test_plan_from_a_point_far_beyond_the_map_is_one_line(tmp_path: Path) -> None:
    """A RuntimeWarning (overflow, then an invalid cast) came before the message."""
    args = ["plan", "lab-8x6", "--from", "1e308,1", "--to", "2,2", "--out", str(tmp_path / "p")]
    assert _refused_in_one_line(args) == "--from 1e+308,1: outside the map lab-8x6"


def test_navigate_takes_a_shipped_world_name_as_its_map(tmp_path: Path) -> None:
    """``--map lab-8x6`` was "cannot read" in navigate while plan accepted it."""
    out = tmp_path / "nav.mcap"
    args = ["navigate", "--world", "lab-8x6", "--map", "lab-8x6", *_LEGS, "--out", str(out)]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    assert "leg 1 to (2.5, 1.2) (waypoint): plan ok" in res.output
    assert (tmp_path / "nav").is_dir() and (tmp_path / "nav.png").is_file()


def test_a_map_that_is_not_the_worlds_is_warned(tmp_path: Path) -> None:
    """Found by a new user: ``--world warehouse-20x20 --map lab-8x6`` ran, exit 0, with no
    word that 28 % of the scan matches were refused."""
    out = tmp_path / "nav.mcap"
    args = ["navigate", "--world", "warehouse-20x20", "--map", "lab-8x6", *_LEGS, "--out", str(out)]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    warned = [line for line in res.stderr.splitlines() if "omnical: warning:" in line]
    said = "the scans matched --map lab-8x6 only 72 % of the time: is it a map of --world"
    assert warned == [f"omnical: warning: {said} warehouse-20x20?"]


def test_plan_inflates_by_the_named_robots_footprint(tmp_path: Path) -> None:
    """Issue 29: plan inflated by a generic 0.6 m footprint whatever the robot and named none.
    A robot 1.4 m wide cannot reach a goal the preset reaches in lab-8x6."""
    wide = tmp_path / "wide.yaml"
    wide.write_text(
        "base: rosy-mecanum\nname: wide\nfootprint_m: {length_m: 1.4, width_m: 1.4}\n",
        encoding="utf-8",
    )
    args = ["plan", "lab-8x6", "--from", "1.5,1.2", "--to", "6.5,3", "--out"]
    preset = CliRunner().invoke(app, [*args, str(tmp_path / "a.csv")])
    assert preset.exit_code == 0, preset.output
    assert "robot: rosy-mecanum (preset)" in preset.output
    assert "circumscribed radius 0.424 m" in preset.output
    res = CliRunner().invoke(app, [*args, str(tmp_path / "b.csv"), "--robot", str(wide)])
    assert f"robot: wide (file {wide})" in res.output
    assert "circumscribed radius 0.990 m" in res.output
    assert res.exit_code == 3 and "goal_in_collision" in res.output, res.output


@pytest.mark.parametrize("extra", [["--margin", "5"], ["--area", "0,0,8,6"]])
def test_serial_only_options_on_the_twin_are_refused(tmp_path: Path, extra: list[str]) -> None:
    """Issue 29: ``navigate --margin`` was accepted silently on the twin (it applies to a robot
    over serial only, as --area and --hedge, which were refused)."""
    out = ["--out", str(tmp_path / "out.mcap")]
    args = ["navigate", "--world", "lab-8x6", "--map", "lab-8x6", *_LEGS, *out, *extra]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2, res.output
    assert "--margin, --time-scale and --twist-stamped apply to a real robot only" in res.output
    assert not list(tmp_path.iterdir())

"""Every command that writes checks its outputs first: a user's own files are never replaced."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app

runner = CliRunner()


@pytest.fixture(scope="module")
def run_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("bag") / "run.mcap"
    result = runner.invoke(app, ["simulate", "straight-10m", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


def test_locate_never_replaces_a_users_csv_and_checks_before_the_work(
    run_bag: Path, tmp_path: Path
) -> None:
    mine = tmp_path / "mine.csv"
    mine.write_text("precious\n", encoding="utf-8")
    for extra in ([], ["--overwrite"]):
        result = runner.invoke(app, ["locate", str(run_bag), "--out", str(mine), *extra])
        assert result.exit_code == 2, result.output
        assert "not written by omnical" in result.output
    assert mine.read_text(encoding="utf-8") == "precious\n"
    result = runner.invoke(app, ["locate", str(run_bag), "--out", "/proc/self/fixes.csv"])
    assert result.exit_code == 2 and "cannot write" in result.output  # before multilaterating
    ours = tmp_path / "fixes.csv"
    assert runner.invoke(app, ["locate", str(run_bag), "--out", str(ours)]).exit_code == 0
    again = runner.invoke(app, ["locate", str(run_bag), "--out", str(ours)])
    assert again.exit_code == 2 and "add --overwrite" in again.output
    args = ["locate", str(run_bag), "--out", str(ours), "--overwrite"]
    assert runner.invoke(app, args).exit_code == 0


def test_evaluate_refuses_a_directory_of_the_users_files(run_bag: Path, tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "path.png").write_bytes(b"my own figure")
    for extra in ([], ["--overwrite"]):
        result = runner.invoke(app, ["evaluate", str(run_bag), "--out", str(mine), *extra])
        assert result.exit_code == 2, result.output
        assert "not written by omnical" in result.output
    assert (mine / "path.png").read_bytes() == b"my own figure"


def test_run_on_the_twin_installs_the_factors_it_is_given(tmp_path: Path) -> None:
    factors = tmp_path / "f.yaml"
    factors.write_text(
        "# omnical\nscale: {longitudinal: 1.02, lateral: 1.13, rotational: 1.0236}\n"
        "crosstalk_rad_per_m: {forward: 0, reverse: 0, left: 0, right: 0}\n",
        encoding="utf-8",
    )
    out = tmp_path / "r.mcap"
    args = ["run", "straight-10m", "--robot", "twin", "--hedge", "twin", "--yes", "--out", str(out)]
    result = runner.invoke(app, [*args, "--factors", str(factors)])
    assert result.exit_code == 0, result.output
    assert "installed" in result.output
    bad = runner.invoke(app, [*args[:-1], str(tmp_path / "r2.mcap"), "--factors", "/nope.yaml"])
    assert bad.exit_code == 2 and "nope.yaml" in bad.output


def test_evaluate_on_the_omni_x_robot_measures_seed_003s_estimate(tmp_path: Path) -> None:
    import json

    bag = tmp_path / "omni.mcap"
    sim = ["simulate", "straight-10m", "--robot", "omni-x", "--out", str(bag)]
    assert runner.invoke(app, sim).exit_code == 0
    out = tmp_path / "ev"
    result = runner.invoke(app, ["evaluate", str(bag), "--robot", "omni-x", "--out", str(out)])
    assert result.exit_code == 0, result.output
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    # the dead wheels + IMU estimate beats the omni wheels' own odometry on the omni-X twin
    assert metrics["seed003"]["rmse_m"] < metrics["odometry"]["rmse_m"]
    assert (out / "path.png").is_file()  # the figures draw the dead-wheel estimate too


@pytest.mark.parametrize("device", ["/dev/full", "/dev/zero"])
def test_a_device_is_refused_unread_as_an_output(
    run_bag: Path, tmp_path: Path, device: str
) -> None:
    """Issue 28: /dev/full was read without end by the "did omnical write this" check (a
    MemoryError after 20 s); every output kind refuses it in one line, before any work."""
    if not Path(device).exists():
        pytest.skip(f"no {device}")
    for args in (
        ["locate", str(run_bag), "--out", device, "--overwrite"],
        ["simulate", "straight-10m", "--out", device, "--overwrite"],
        ["evaluate", str(run_bag), "--out", device, "--overwrite"],
        ["plan", "lab-8x6", "--from", "1,1", "--to", "6.5,1", "--out", device, "--overwrite"],
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        line = f"omnical: error: {device}: "
        assert result.output.startswith(line) and result.output.count("\n") == 1, result.output


def test_overwrite_never_replaces_a_users_file_through_a_link(
    run_bag: Path, tmp_path: Path
) -> None:
    """Issue 28: a link to a user's file whose text says "omnical" was replaced."""
    mine = tmp_path / "my-notes.yaml"
    mine.write_text("# notes on omnical: the factors I trust\n", encoding="utf-8")
    link = tmp_path / "rosy.yaml"
    link.symlink_to(mine)
    result = runner.invoke(
        app, ["calibrate", "estimate", str(run_bag), "--out", str(link), "--overwrite"]
    )
    assert result.exit_code == 2, result.output
    assert f"omnical: error: {link}: is a symbolic link to {mine}" in result.output
    assert result.output.count("\n") == 1
    assert mine.read_text(encoding="utf-8") == "# notes on omnical: the factors I trust\n"
    assert link.is_symlink()
    mine.write_text("# omnical calibrate estimate run.mcap\n", encoding="utf-8")
    link.unlink()
    mine.rename(link)  # the word in its text is no marker either, link or not
    result = runner.invoke(
        app, ["calibrate", "estimate", str(run_bag), "--out", str(link), "--overwrite"]
    )
    assert result.exit_code == 2 and "exists and was not written by omnical" in result.output
    assert link.read_text(encoding="utf-8") == "# omnical calibrate estimate run.mcap\n"


def test_a_failed_evaluation_leaves_nothing_behind(run_bag: Path, tmp_path: Path) -> None:
    out = tmp_path / "deep" / "ev"
    args = ["evaluate", str(run_bag), "--out", str(out), "--reference", "circel"]
    result = runner.invoke(app, args)
    assert result.exit_code == 2 and "circel" in result.output
    assert not any(tmp_path.iterdir())  # no output, no staging, not even the parent made


def test_a_full_disk_names_the_file_and_keeps_the_earlier_evaluation(
    run_bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """ENOSPC while a figure is written (matplotlib's write names no file): one line naming
    the file, exit 2; the earlier evaluation untouched, what was written kept as .partial."""
    import errno
    import os

    from matplotlib.figure import Figure

    out = tmp_path / "ev"
    assert runner.invoke(app, ["evaluate", str(run_bag), "--out", str(out)]).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def full(self: Figure, fname: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Figure, "savefig", full)
    result = runner.invoke(app, ["evaluate", str(run_bag), "--out", str(out), "--overwrite"])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    line = result.output.strip().splitlines()[-1]
    assert line == (
        f"omnical: error: {out / 'path.png'}: cannot write: No space left on device; what was "
        f"written is kept in {tmp_path / 'ev.partial'}, the earlier {out} was not touched"
    )
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert (tmp_path / "ev.partial" / "metrics.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ev", "ev.partial"]

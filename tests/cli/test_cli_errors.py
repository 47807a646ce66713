"""The CLI's contract on failure (exit 2 / 1 / 130) and its light start-up."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.cli.errors import BUG_MESSAGE, EXIT_BAD_INPUT, EXIT_BUG, EXIT_INTERRUPTED
from omnical.cli.main import app

runner = CliRunner()


@pytest.fixture(scope="module")
def tiny_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from omnical.bags.bag import write_bag
    from omnical.recording.recording import RecordingBuilder

    builder = RecordingBuilder()
    for k in range(5):
        t_ns = 1_000_000_000 + k * 20_000_000
        builder.add("/cmd_vel", t_ns, vx_mps=0.1, vy_mps=0.0, wz_radps=0.0)
    return write_bag(builder.build(), tmp_path_factory.mktemp("tiny") / "tiny.mcap")


def test_a_bag_rosbags_cannot_read_is_a_user_error(tmp_path: Path) -> None:
    bag = tmp_path / "corrupt.bag"
    bag.write_bytes(b"#ROSBAG V2.0\n" + b"\x00garbage" * 50)
    result = runner.invoke(app, ["info", str(bag)])
    assert result.exit_code == EXIT_BAD_INPUT
    assert f"omnical: error: {bag}: cannot read bag" in result.output
    assert "Traceback" not in result.output


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs")
@pytest.mark.parametrize(
    "command",
    [["info"], ["locate", "--out", "x.csv"], ["export", "--format", "csv", "--out", "d"]],
)
def test_a_fifo_for_a_bag_is_one_line_and_exit_2(tmp_path: Path, command: list[str]) -> None:
    """Every command reading a bag refuses a FIFO before opening it (it waited for ever)."""
    fifo = tmp_path / "fifo.mcap"
    os.mkfifo(fifo)
    out = [str(tmp_path / a) if a in {"x.csv", "d"} else a for a in command[1:]]
    done = subprocess.run(
        [sys.executable, "-m", "omnical.cli.main", command[0], str(fifo), *out],
        capture_output=True,
        text=True,
        timeout=10,
        check=False,
    )
    assert done.returncode == EXIT_BAD_INPUT
    assert (
        done.stderr == f"omnical: error: {fifo}: is not a regular file (a FIFO), expected a bag\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo.mcap"]


def test_an_internal_bug_is_exit_1_with_its_traceback(
    tiny_bag: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from omnical.bags import bag

    def broken(*_args: object) -> None:
        msg = "internal invariant violated"
        raise RuntimeError(msg)

    monkeypatch.setattr(bag, "recognise_topic", broken)  # inside read_bag's try block
    result = runner.invoke(app, ["info", str(tiny_bag)])
    assert result.exit_code == EXIT_BUG
    assert "Traceback" in result.output
    assert "RuntimeError: internal invariant violated" in result.output
    assert result.output.rstrip().endswith(BUG_MESSAGE)
    assert "cannot read bag" not in result.output


def test_ctrl_c_is_exit_130_without_traceback(
    tiny_bag: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from omnical.recording import summary

    def interrupted(*_args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(summary, "summarize", interrupted)
    result = runner.invoke(app, ["info", str(tiny_bag)])
    assert result.exit_code == EXIT_INTERRUPTED
    assert result.output.strip() == "omnical: interrupted"


def test_info_on_a_tiny_bag(tiny_bag: Path) -> None:
    result = runner.invoke(app, ["info", str(tiny_bag)])
    assert result.exit_code == 0, result.output
    assert "/cmd_vel" in result.output and "duration: 0.08 s" in result.output


@pytest.mark.parametrize(
    "command",
    [
        [],
        ["simulate"],
        ["info"],
        ["export"],
        ["locate"],
        ["evaluate"],
        ["demo"],
        ["calibrate"],
        ["calibrate", "campaign"],
        ["calibrate", "estimate"],
    ],
)
def test_every_help_page(command: list[str]) -> None:
    result = runner.invoke(app, [*command, "--help"])
    assert result.exit_code == 0, result.output
    assert "Usage: omnical" in result.output


def test_calibrate_lists_its_two_commands() -> None:
    result = runner.invoke(app, ["calibrate", "--help"])
    assert "campaign" in result.output and "estimate" in result.output


def test_importing_the_cli_imports_nothing_heavy() -> None:
    code = (
        "import sys\n"
        "import omnical.cli.main\n"
        "heavy = ('numpy', 'scipy', 'matplotlib', 'rosbags', 'rich.progress', 'pydantic', 'yaml')\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in heavy or m in heavy))\n"
        "print(sorted(m for m in sys.modules if m.startswith('omnical.') and\n"
        "             not m.startswith(('omnical.cli', 'omnical.choices', 'omnical.errors'))))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert proc.stdout.split("\n")[:2] == ["[]", "[]"], proc.stdout


def test_a_misspelt_builtin_twin_names_the_builtins(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["simulate", "tour", "--twin", "defualt", "--out", str(tmp_path / "r.mcap")]
    )
    assert result.exit_code == 2
    assert "defualt: no such twin file, and not a built-in twin ('default' or 'ideal')" in (
        result.output
    )


def test_an_nlos_zone_of_an_unknown_beacon_names_the_file_before_the_run(tmp_path: Path) -> None:
    """Found by a new user: 'nlos_zones: beacon 99 is not in the beacon map' named no file and
    came after the run had started."""
    twin = tmp_path / "nlos.yaml"
    twin.write_text("ips: {nlos_zones: [{beacon: 99, rectangle: [0, 0, 1, 1], bias_m: 0.4}]}\n")
    out = tmp_path / "run.mcap"
    result = runner.invoke(app, ["simulate", "square", "--twin", str(twin), "-o", str(out)])
    assert result.exit_code == EXIT_BAD_INPUT
    assert result.output.strip().endswith(
        f"{twin}: ips.nlos_zones[0].beacon: 99 is not in the beacon map (beacons 3, 4, 5, 6)"
    )
    assert not out.exists() and not list(tmp_path.glob("run*partial*"))


def test_a_serial_run_with_nobody_to_confirm_is_refused_before_any_work(tmp_path: Path) -> None:
    from omnical.cli.serial_options import confirm_first_motion

    out = tmp_path / "cal"
    args = ["calibrate", "campaign", "--robot", "serial:/dev/omnical-none"]
    result = runner.invoke(app, [*args, "--hedge", "serial:/dev/omnical-none2", "--out", str(out)])
    assert result.exit_code == EXIT_BAD_INPUT
    assert "no terminal to confirm the first motion on: add --yes" in result.output
    assert not out.exists()
    assert confirm_first_motion("move?", yes=True)  # --yes: nothing asked


def test_a_stop_an_extension_turned_into_its_own_error_is_a_stop() -> None:
    """A Ctrl-C while a C extension initialised (gtsam on a fresh venv's first import) came
    back as "ImportError: initialization failed" and was reported as a bug, exit 1."""
    import typer

    from omnical.cli.errors import Terminated, handled_errors

    for stop, status in ((KeyboardInterrupt(), 130), (Terminated(), 143)):
        with pytest.raises(typer.Exit) as exited, handled_errors():
            try:
                raise stop
            except KeyboardInterrupt as err:
                raise ImportError("initialization failed") from err
        assert exited.value.exit_code == status
    with pytest.raises(typer.Exit) as exited, handled_errors():
        raise ImportError("a real bug")
    assert exited.value.exit_code == 1


def test_the_twin_pause_note_is_for_a_silent_vehicle_controller_on_a_pty_only() -> None:
    from omnical.cli.errors import _twin_pause_can_explain
    from omnical.errors import SafetyStopError

    def stop(device: str, detail: str) -> SafetyStopError:
        return SafetyStopError(device, 0.2, detail)

    pty = "vehicle controller on /dev/pts/3"
    assert _twin_pause_can_explain(stop(pty, "nothing received"))
    assert _twin_pause_can_explain(stop(pty, "23 bytes received, none valid"))  # a cut frame
    assert not _twin_pause_can_explain(stop(pty, "240 bytes received, none valid"))  # garbage
    assert not _twin_pause_can_explain(stop(pty, "port failed: [Errno 5] EIO"))
    assert not _twin_pause_can_explain(stop("hedgehog on /dev/pts/4", "nothing received"))
    assert not _twin_pause_can_explain(
        stop("vehicle controller on /dev/ttyUSB0", "nothing received")
    )

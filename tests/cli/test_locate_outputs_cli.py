"""``omnical locate``'s outputs: the library's fixes, the output replaced only once complete,
errors in one line, and Ctrl-C / SIGTERM clean in the middle of the work."""

from __future__ import annotations

import errno
import importlib.util
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType

import pytest
from typer.testing import CliRunner

from omnical.bags.bag import write_bag
from omnical.cli.main import app
from omnical.ips.from_recording import locate, write_fixes_csv
from omnical.recording.recording import Recording

runner = CliRunner()


def _ips_synthetic() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "ips" / "ips_synthetic.py"
    spec = importlib.util.spec_from_file_location("ips_synthetic", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("ips_synthetic", module)
    spec.loader.exec_module(module)
    return module


synthetic = _ips_synthetic()


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Recording]:
    recording: Recording = synthetic.hedgehogs_on_circles(hedges=3, seconds=240.0)
    return write_bag(recording, tmp_path_factory.mktemp("bag") / "three.mcap"), recording


def test_cli_writes_the_librarys_fixes(bag: tuple[Path, Recording], tmp_path: Path) -> None:
    path, recording = bag
    fixes, _ = locate(recording)
    write_fixes_csv(fixes, tmp_path / "library.csv")
    out = tmp_path / "cli.csv"
    result = runner.invoke(app, ["locate", str(path), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_bytes() == (tmp_path / "library.csv").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cli.csv", "library.csv"]


def test_with_a_plot_the_same_fixes(bag: tuple[Path, Recording], tmp_path: Path) -> None:
    """``--plot`` adds the figure; the CSV and what is said of the fixes are the same."""
    path, _ = bag
    plain = runner.invoke(app, ["locate", str(path), "--out", str(tmp_path / "a.csv")])
    plotted = runner.invoke(
        app,
        ["locate", str(path), "--out", str(tmp_path / "b.csv"), "--plot", str(tmp_path / "b.png")],
    )
    assert plain.exit_code == plotted.exit_code == 0, plotted.output
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    assert (tmp_path / "b.png").read_bytes().startswith(b"\x89PNG")
    assert (
        plotted.output.replace("b.csv", "a.csv") == plain.output + f"wrote {tmp_path / 'b.png'}\n"
    )


def test_a_damaged_bag_is_one_line_and_no_output(
    bag: tuple[Path, Recording], tmp_path: Path
) -> None:
    """A truncated bag: exit 2, one line, no traceback, and no output written."""
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    for part in bag[0].iterdir():
        data = part.read_bytes()
        (damaged / part.name).write_bytes(
            data[: len(data) // 2] if part.suffix == ".mcap" else data
        )
    done = subprocess.run(
        [sys.executable, "-m", "omnical.cli.main", "locate", str(damaged), "--out",
         str(tmp_path / "a.csv")],
        capture_output=True, text=True, check=False, timeout=300,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.splitlines()) == 1 and "Traceback" not in done.stderr
    assert done.stderr.startswith("omnical: error: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["damaged"]


def _holds_open(pid: int, folder: Path) -> bool:
    """Whether process ``pid`` has a file of ``folder`` open (it is reading the bag)."""
    try:
        links = [str(fd.readlink()) for fd in Path(f"/proc/{pid}/fd").iterdir()]
    except OSError:  # ended, or a descriptor closed meanwhile
        return False
    return any(link.startswith(str(folder)) for link in links)


def _stopped_reading(proc: subprocess.Popen[str], folder: Path) -> bool:
    """Stop ``proc`` (SIGSTOP) at a moment it has a file of ``folder`` open; False if it ends
    first. Stopped, it cannot close the file before a signal sent now reaches it."""
    deadline = time.monotonic() + 60.0
    while proc.poll() is None and time.monotonic() < deadline:
        if _holds_open(proc.pid, folder):
            os.kill(proc.pid, signal.SIGSTOP)
            stopping = time.monotonic() + 5.0  # ``t``: stopped under a tracer (strace, py-spy)
            while (state := _state(proc.pid)) not in "TtZX?" and time.monotonic() < stopping:
                time.sleep(0.001)
            if state in "Tt" and _holds_open(proc.pid, folder):
                return True
            os.kill(proc.pid, signal.SIGCONT)
        time.sleep(0.002)
    return False


def _state(pid: int) -> str:
    """The state letter of process ``pid`` (``T`` stopped, ``Z`` ended; ``?`` gone)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "?"


@pytest.mark.slow
@pytest.mark.parametrize(
    ("sig", "status", "word"),
    [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")],
)
def test_a_signal_while_the_bag_is_read(
    bag: tuple[Path, Recording], tmp_path: Path, sig: signal.Signals, status: int, word: str
) -> None:
    """Ctrl-C (to the whole process group, as a terminal sends it) or SIGTERM (to omnical
    alone) while the bag is read: one line, the exit status, the old output kept, no partial
    file left."""
    out = tmp_path / "fixes.csv"
    runner.invoke(app, ["locate", str(bag[0]), "--out", str(out)])
    before = out.read_bytes()
    # the console script's entry, not ``python -m``: a Ctrl-C that passes through an
    # ``exec`` of a string (as dataclasses make their methods) makes ``python -m`` end by
    # SIGINT whatever the status asked (CPython's _Py_UnhandledKeyboardInterrupt)
    proc = subprocess.Popen(
        [sys.executable, "-c", "from omnical.cli.entry import main; main()", "locate",
         str(bag[0]), "--out", str(out), "--overwrite"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    try:
        assert _stopped_reading(proc, bag[0].parent), "never seen reading the bag"
        # stopped while it holds the bag open: the signal waits for it there
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        os.kill(proc.pid, signal.SIGCONT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)  # never left stopped
            proc.kill()
            proc.communicate()
    assert proc.returncode == status, err
    assert err == f"omnical: {word}\n"
    assert out.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["fixes.csv"]


def test_out_through_a_symbolic_link_replaces_the_file_it_points_to(
    bag: tuple[Path, Recording], tmp_path: Path
) -> None:
    """A link kept as a link (it had been replaced by a plain file)."""
    path, _ = bag
    target = tmp_path / "data" / "fixes.csv"
    target.parent.mkdir()
    link = tmp_path / "latest.csv"
    link.symlink_to(target)
    result = runner.invoke(app, ["locate", str(path), "--out", str(link)])
    assert result.exit_code == 0, result.output
    assert link.is_symlink()
    assert target.read_text().startswith("t_ns,")
    assert sorted(p.name for p in target.parent.iterdir()) == ["fixes.csv"]


def test_an_os_error_of_omnicals_own_is_still_a_bug(
    bag: tuple[Path, Recording], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A bad file descriptor is omnical's mistake, not the machine's: traceback, exit 1."""
    from omnical.ips import from_recording

    def broken(*args: object, **kwargs: object) -> object:
        raise OSError(errno.EBADF, os.strerror(errno.EBADF))

    monkeypatch.setattr(from_recording, "locate", broken)
    result = runner.invoke(app, ["locate", str(bag[0]), "--out", str(tmp_path / "f.csv")])
    assert result.exit_code == 1, result.output
    assert "this is a bug in omnical" in result.output


def test_a_failed_write_of_the_csv_names_the_output(
    bag: tuple[Path, Recording], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The disk full while the CSV is written: the output named (not its hidden partial
    file), exit 2, the earlier CSV kept."""
    from omnical.ips import from_recording

    path, _ = bag
    out = tmp_path / "fixes.csv"
    assert runner.invoke(app, ["locate", str(path), "--out", str(out)]).exit_code == 0
    before = out.read_bytes()

    def full(fixes: object, path: Path) -> Path:
        path.write_text("t_ns,")  # a part written, then the disk full
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(from_recording, "write_fixes_csv", full)
    result = runner.invoke(app, ["locate", str(path), "--out", str(out), "--overwrite"])
    assert result.exit_code == 2, result.output
    assert f"omnical: error: {out}: cannot write: No space left on device" in result.output
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fixes.csv"]


def test_a_symbolic_link_loop_is_refused_before_any_work(
    bag: tuple[Path, Recording], tmp_path: Path
) -> None:
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.symlink_to(b)
    b.symlink_to(a)
    result = runner.invoke(app, ["locate", str(bag[0]), "--out", str(a)])
    assert result.exit_code == 2, result.output
    assert f"omnical: error: {a}: is a symbolic link that loops" in result.output
    assert a.is_symlink() and b.is_symlink()


def test_a_dangling_link_into_a_new_directory_is_written_through(
    bag: tuple[Path, Recording], tmp_path: Path
) -> None:
    link = tmp_path / "latest.csv"
    link.symlink_to(tmp_path / "runs" / "today.csv")
    result = runner.invoke(app, ["locate", str(bag[0]), "--out", str(link)])
    assert result.exit_code == 0, result.output
    assert link.is_symlink()
    assert (tmp_path / "runs" / "today.csv").read_text().startswith("t_ns,")


def test_many_hedgehogs_print_one_line_each(tmp_path: Path) -> None:
    """Nine hedgehogs: each model's summary line, not its links (three: every link)."""
    recording: Recording = synthetic.hedgehogs_on_circles(hedges=9, seconds=20.0)
    bag = write_bag(recording, tmp_path / "nine.mcap")
    result = runner.invoke(app, ["locate", str(bag), "--out", str(tmp_path / "f.csv")])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert sum(line.startswith("hedgehog ") for line in lines) == 9
    assert not any(line.startswith("  beacon ") for line in lines)
    assert "(each link's σ, bias and scale left out for 9 hedgehogs)" in lines


def test_a_few_hedgehogs_print_every_link(bag: tuple[Path, Recording], tmp_path: Path) -> None:
    result = runner.invoke(app, ["locate", str(bag[0]), "--out", str(tmp_path / "f.csv")])
    assert result.exit_code == 0, result.output
    assert sum(line.startswith("  beacon ") for line in result.output.splitlines()) >= 3 * 3

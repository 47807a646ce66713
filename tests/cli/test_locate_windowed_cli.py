"""``omnical locate`` a window at a time (issue "Scale"): the library's fixes, the output
replaced only once complete, and Ctrl-C / SIGTERM clean while a second process learns."""

from __future__ import annotations

import importlib.util
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest
from typer.testing import CliRunner

from omnical.cli.main import app
from omnical.ips.from_recording import locate, write_fixes_csv
from omnical.recording.bag import write_bag
from omnical.recording.recording import Recording

runner = CliRunner()


def _windowed_tests() -> ModuleType:
    path = Path(__file__).resolve().parents[1] / "ips" / "test_locate_windowed.py"
    spec = importlib.util.spec_from_file_location("test_locate_windowed_helpers", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


helpers = _windowed_tests()


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Recording]:
    recording: Recording = helpers._synthetic(hedges=3, seconds=240.0)
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


_FORKING = (
    "import omnical.ips.windowed as w; w.PARALLEL_FIXES = 0; "
    "from omnical.cli.main import main; main()"
)
_ASIDE = (  # the bag read in a forked process, numba loaded meanwhile (3 hedgehogs as many)
    "import omnical.ips.windowed as w; w.PARALLEL_FIXES = 0; "
    "import omnical.cli.locate as c; c._ASIDE_BYTES = 0; "
    "import omnical.ips.solve.locate as s; s.MANY_STREAMS = 2; "
    "from omnical.cli.main import main; main()"
)


def _omnical(code: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True,
        text=True,
        check=False,
        timeout=300,
    )


def test_cli_reading_aside_writes_the_librarys_fixes(
    bag: tuple[Path, Recording], tmp_path: Path
) -> None:
    """The bag read in a second process (its ranges on disk handed back open) while this one
    loads the compiled solver, then two processes learn: the same bytes."""
    path, recording = bag
    fixes, _ = locate(recording)
    write_fixes_csv(fixes, tmp_path / "library.csv")
    out = tmp_path / "cli.csv"
    done = _omnical(_ASIDE, "locate", str(path), "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert out.read_bytes() == (tmp_path / "library.csv").read_bytes()


def test_a_reading_process_that_fails_leaves_the_bag_to_be_read_here(
    bag: tuple[Path, Recording], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The reading process dies (out of memory, a bug): the bag is read again here."""
    from omnical.cli import locate as cli_locate
    from omnical.ips.solve import locate as solve_locate

    here = os.getpid()
    read = cli_locate._read_ranges
    where: list[int] = []

    def fails_there(path: Path) -> Any:
        if os.getpid() != here:
            os._exit(9)
        where.append(os.getpid())
        return read(path)

    monkeypatch.setattr(cli_locate, "_ASIDE_BYTES", 0)
    monkeypatch.setattr(solve_locate, "MANY_STREAMS", 2)
    monkeypatch.setattr(cli_locate, "_read_ranges", fails_there)
    ranges = cli_locate._read_ranges_aside(bag[0])
    assert where == [here]
    assert ranges.raw.rows == read(bag[0]).raw.rows > 0


def test_a_damaged_bag_read_aside_says_what_it_says_read_here(
    bag: tuple[Path, Recording], tmp_path: Path
) -> None:
    """The reading process fails on a truncated bag: the bag is read again here, which
    raises the error as ever (one line, exit 2), and no output is written."""
    source = bag[0]
    damaged = tmp_path / "damaged"
    damaged.mkdir()
    for part in source.iterdir():
        data = part.read_bytes()
        (damaged / part.name).write_bytes(
            data[: len(data) // 2] if part.suffix == ".mcap" else data
        )
    here = _omnical(_FORKING, "locate", str(damaged), "--out", str(tmp_path / "a.csv"))
    aside = _omnical(_ASIDE, "locate", str(damaged), "--out", str(tmp_path / "b.csv"))
    assert here.returncode == aside.returncode == 2, aside.stderr
    assert aside.stderr == here.stderr.replace("a.csv", "b.csv")
    assert len(aside.stderr.splitlines()) == 1 and "Traceback" not in aside.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["damaged"]


@pytest.mark.slow
@pytest.mark.parametrize("code", [_FORKING, _ASIDE], ids=["learning", "reading"])
@pytest.mark.parametrize(
    ("sig", "status", "word"),
    [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")],
)
def test_a_signal_while_two_processes_learn(
    bag: tuple[Path, Recording],
    tmp_path: Path,
    sig: signal.Signals,
    status: int,
    word: str,
    code: str,
) -> None:
    """Ctrl-C (to the whole process group, as a terminal sends it) or SIGTERM (to omnical
    alone) while a second process runs (learning, or reading the bag): one line, the exit
    status, the old output kept, no process left behind."""
    out = tmp_path / "fixes.csv"
    runner.invoke(app, ["locate", str(bag[0]), "--out", str(out)])
    before = out.read_bytes()
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "locate", str(bag[0]), "--out", str(out), "--overwrite"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    child = ""
    deadline = time.monotonic() + 60.0
    while not child and proc.poll() is None and time.monotonic() < deadline:
        child = subprocess.run(
            ["pgrep", "-P", str(proc.pid)], capture_output=True, text=True, check=False
        ).stdout.strip()
        time.sleep(0.005)
    if not child:
        proc.communicate()
        pytest.skip("the run ended before its learning process was seen")
    if sig == signal.SIGINT:
        os.killpg(proc.pid, sig)
    else:
        proc.send_signal(sig)
    try:
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    if proc.returncode == 0:
        pytest.skip("the run ended before the signal reached it")
    assert proc.returncode == status, err
    assert err == f"omnical: {word}\n"
    assert out.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["fixes.csv"]
    time.sleep(0.2)
    for pid in child.split():
        assert not Path(f"/proc/{pid}").exists() or "Z" in Path(f"/proc/{pid}/stat").read_text()


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


def test_a_full_disk_is_one_line_and_the_old_output_stays(
    bag: tuple[Path, Recording], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """ENOSPC while the ranges are spilled to a temporary file: exit 2, no traceback, the
    earlier CSV untouched and no partial file left."""
    import errno

    import omnical.ips.windowed as windowed

    path, _ = bag
    out = tmp_path / "fixes.csv"
    assert runner.invoke(app, ["locate", str(path), "--out", str(out)]).exit_code == 0
    before = out.read_bytes()

    def full(fd: int, data: bytes, offset: int) -> int:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(windowed.os, "pwrite", full)
    result = runner.invoke(app, ["locate", str(path), "--out", str(out), "--overwrite"])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert "omnical: error: a temporary file in " in result.output
    assert "(TMPDIR): No space left on device" in result.output
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fixes.csv"]


def test_an_os_error_of_omnicals_own_is_still_a_bug(
    bag: tuple[Path, Recording], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A bad file descriptor is omnical's mistake, not the machine's: traceback, exit 1."""
    import errno

    import omnical.ips.windowed as windowed

    def broken(self: object, records: object) -> None:
        raise OSError(errno.EBADF, os.strerror(errno.EBADF))

    monkeypatch.setattr(windowed.Spill, "append", broken)
    result = runner.invoke(app, ["locate", str(bag[0]), "--out", str(tmp_path / "f.csv")])
    assert result.exit_code == 1, result.output
    assert "this is a bug in omnical" in result.output


def test_a_failed_write_of_the_csv_names_the_output(
    bag: tuple[Path, Recording], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The disk full while the CSV is written: the output named (not its hidden partial
    file), exit 2, the earlier CSV kept."""
    import errno

    from omnical.ips import from_recording

    path, _ = bag
    out = tmp_path / "fixes.csv"
    assert runner.invoke(app, ["locate", str(path), "--out", str(out)]).exit_code == 0
    before = out.read_bytes()

    def full(self: object, fixes: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(from_recording.FixesCsv, "write", full)
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
    recording: Recording = helpers._synthetic(hedges=9, seconds=20.0)
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


def test_reading_aside_hands_back_what_reading_here_gives(
    bag: tuple[Path, Recording], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The ranges, beacons and vendor heights the reading process hands back are those read
    here; this process loads the compiled solver only for as many hedgehogs as take it."""
    from omnical.cli import locate as cli_locate
    from omnical.ips import forked
    from omnical.ips.solve import _fit
    from omnical.ips.solve import locate as solve_locate

    loaded: list[bool] = []
    monkeypatch.setattr(_fit, "load_compiled", lambda: loaded.append(True))
    monkeypatch.setattr(cli_locate, "_ASIDE_BYTES", 0)
    collected: list[object] = []
    collect = forked.collect

    def spied(child: Any) -> Any:
        collected.append(collect(child))
        return collected[-1]

    monkeypatch.setattr(forked, "collect", spied)
    here = cli_locate._read_ranges(bag[0])
    assert here.hedges.size == 3
    for many, want in ((3, [True]), (4, [])):
        loaded.clear()
        monkeypatch.setattr(solve_locate, "MANY_STREAMS", many)
        collected.clear()
        aside = cli_locate._read_ranges_aside(bag[0])
        assert loaded == want
        # read there (the RangeRun handed back is the one returned), or here: no process
        assert [r is aside for r in collected] == [True] * len(want)
        assert aside.raw.rows == here.raw.rows > 0
        assert (
            aside.raw.read(0, aside.raw.rows).tobytes() == here.raw.read(0, here.raw.rows).tobytes()
        )
        got = aside.heights.read(0, aside.heights.rows)
        assert got.tobytes() == here.heights.read(0, here.heights.rows).tobytes()
        assert aside.heard.tolist() == here.heard.tolist()
        assert aside.hedges.tolist() == here.hedges.tolist()
        assert aside.beacon_rows is not None and here.beacon_rows is not None
        assert {k: v.tolist() for k, v in aside.beacon_rows.items()} == {
            k: v.tolist() for k, v in here.beacon_rows.items()
        }
        assert (aside.vendor, aside.nan_heights) == (here.vendor, here.nan_heights)
        aside.close()
    here.close()

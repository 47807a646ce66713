"""``omnical``'s exit without the interpreter's teardown (:func:`omnical.cli.main.leave`): the
status, the output and the files are what the usual exit gives."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


def _run(code: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    script = (
        "import pathlib, sys\nfrom omnical.cli.main import leave\n"
        "where = pathlib.Path(sys.argv[1])\n" + code
    )
    return subprocess.run(
        [sys.executable, "-c", script, str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


@pytest.mark.parametrize(("code", "status"), [("None", 0), ("3", 3), ("130", 130)])
def test_status_and_buffered_output(tmp_path: Path, code: str, status: int) -> None:
    done = _run(
        f"print('out', end=''); print('err', end='', file=sys.stderr); leave({code})", tmp_path
    )
    assert (done.returncode, done.stdout, done.stderr) == (status, "out", "err")


def test_a_message_is_printed_with_status_1(tmp_path: Path) -> None:
    done = _run("leave('omnical: gone')", tmp_path)
    assert (done.returncode, done.stderr) == (1, "omnical: gone\n")


_HANDLERS_AND_CYCLES = (
    "import atexit\n"
    "atexit.register(lambda: (where / 'handler').write_text('ran'))\n"
    "class Held:\n"
    "    def __del__(self): (where / 'finaliser').write_text('ran')\n"
    "h = Held(); h.me = h\n"
    "del h\n"
    "leave(0)\n"
)
_A_RUNNING_THREAD = (  # a thread Python waits for (a recorder's writer)
    "import threading, time\n"
    "def late(): time.sleep(0.3); (where / 'late').write_text('ran')\n"
    "threading.Thread(target=late).start()\n"
    "leave(4)\n"
)


@pytest.mark.parametrize(
    ("script", "status", "written"),
    [(_HANDLERS_AND_CYCLES, 0, ("handler", "finaliser")), (_A_RUNNING_THREAD, 4, ("late",))],
)
def test_what_the_usual_exit_would_have_done_is_done(
    tmp_path: Path, script: str, status: int, written: tuple[str, ...]
) -> None:
    """Exit handlers and the finalisers of cycles run; a running thread is waited for."""
    done = _run(script, tmp_path)
    assert done.returncode == status, done.stderr
    assert [(tmp_path / name).read_text() for name in written] == ["ran"] * len(written)


def test_a_process_started_without_stdout(tmp_path: Path) -> None:
    """Started with the descriptor closed (``>&-``), Python's ``sys.stdout`` is None."""
    done = _run("sys.stdout = None\nleave(0)", tmp_path)
    assert (done.returncode, done.stderr) == (0, "")

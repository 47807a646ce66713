"""A stall of the served twin's process neither lengthens a move nor drives it on blind: the
commands sent during it apply at their send times even when they reach the twin well after it
resumed (a loaded host's DDS or executor), and its watchdog stops it at its own time."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = pytest.mark.alone  # wall clock, two processes: see pyproject.toml

CHILD = Path(__file__).with_name("device_stall_child.py")
VX_MPS = 0.2  # for DRIVE_S, then zero until END_S (at rest 0.5 s before); 20 commands a second
DRIVE_S, END_S = 1.0, 2.0
WATCHDOG_S = 0.5  # device_stall_child.py's
Span = tuple[float, float]


@pytest.fixture
def child() -> Iterator[subprocess.Popen[str]]:
    proc = subprocess.Popen(
        [sys.executable, str(CHILD)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        yield proc
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait(timeout=10)


def _drive(
    child: subprocess.Popen[str],
    *,
    stall: Span | None = None,
    tick_stall: Span | None = None,
    held: Span | None = None,
    silent: Span | None = None,
    first_through: bool = False,
    late: bool = False,
    end_s: float = END_S,
) -> tuple[float, float]:
    """One drive; the distance the twin's truth moved, m, and that less what the commands asked
    for as sent (0.2 m/s from the first command to the first zero, or to the watchdog's time
    after the last before a silence): the same whenever this process sent them. ``stall``: the
    twin's process stopped (SIGSTOP) over that span of the drive's time (s); ``tick_stall``: its
    loop held as long in a tick's publishing from the span's start; ``held``: commands sent in
    that span reach it at its end (``first_through``: but the first, sent once a tick's stall
    has begun, which the twin takes as the stall ends); ``late``: the commands sent during a
    tick's stall reach the twin 5 ms after it; ``silent``: none sent in that span; ``end_s``:
    the drive's length (zero commands from DRIVE_S on)."""
    assert child.stdin is not None and child.stdout is not None
    stdin, stdout = child.stdin, child.stdout
    stdin.write("x\n")
    stdin.flush()
    x0 = float(stdout.readline())
    in_flight: list[str] = []
    sent: list[tuple[float, float]] = []  # (drive time, vx)
    t0 = time.monotonic()
    stopped = resumed = False
    while (t := time.monotonic() - t0) < end_s:
        if tick_stall and t >= tick_stall[0]:
            stdin.write(f"stall {tick_stall[1] - tick_stall[0]} {'late' if late else 'ack'}\n")
            stdin.flush()
            tick_stall = None
            # the loop in the tick's stall (it holds the twin's lock there: commands wait on it)
            assert stdout.readline().strip() == "stalled"
        if stall and not stopped and t >= stall[0]:
            os.kill(child.pid, signal.SIGSTOP)
            stopped = True
        if stall and stopped and not resumed and t >= stall[1]:
            os.kill(child.pid, signal.SIGCONT)
            resumed = True
        if not (silent and silent[0] <= t < silent[1]):
            vx = VX_MPS if t < DRIVE_S else 0.0
            in_flight.append(f"{vx} {time.time_ns()}\n")
            sent.append((time.monotonic() - t0, vx))
        if first_through and held and held[0] <= t:
            first_through = False  # this one through, the next ones held
            stdin.write(in_flight.pop())
            stdin.flush()
        if not (held and held[0] <= t < held[1]):
            stdin.write("".join(in_flight))
            stdin.flush()
            in_flight = []
        time.sleep(0.05)
    stdin.write("x\n")
    stdin.flush()
    distance = float(stdout.readline()) - x0
    stops = [t + WATCHDOG_S for t, _ in sent if silent and t < silent[0]][-1:]
    end = stops[0] if stops else min(t for t, vx in sent if vx == 0.0)
    return distance, distance - VX_MPS * (end - sent[0][0])


@pytest.mark.parametrize("where", ["process", "tick", "tick, one waiting"])
def test_commands_delivered_late_after_a_stall_apply_at_their_send_times(
    child: subprocess.Popen[str], where: str
) -> None:
    """Stopped 0.35 s around the zero command at 0.2 m/s (the process, or its loop in a tick's
    publishing), the commands sent from the stall on held back until 0.15 s after it: applied on
    arrival, the move was 6 cm longer (0.2 m/s × the 0.3 s from the zero command to its
    arrival); at their send times, within 1 cm of the same drive without a stall. "One
    waiting": the stall's first command reached the twin during it, and waited there (CI, on a
    loaded host: the twin took it for the ones sent during the stall and waited no more)."""
    plain, plain_rest = _drive(child)
    span, held = (0.85, 1.2), (0.85, 1.35)
    if where == "process":
        stalled, stalled_rest = _drive(child, stall=span, held=held)
    else:
        first_through = where == "tick, one waiting"
        stalled, stalled_rest = _drive(
            child, tick_stall=span, held=held, first_through=first_through
        )
    print(f"the same drive: {plain:.4f} m, {stalled:.4f} m with the stall (beyond what was sent: "
          f"{plain_rest * 1e3:+.1f}, {stalled_rest * 1e3:+.1f} mm)")  # fmt: skip
    assert plain > 0.15  # it moved
    assert abs(stalled_rest - plain_rest) < 0.01, (plain, stalled, plain_rest, stalled_rest)


def test_a_stall_as_a_drive_begins_does_not_start_it_late(
    child: subprocess.Popen[str],
) -> None:
    """The twin's loop held 0.3 s in a tick just as a drive begins (at rest: its watchdog
    stopped it after the last drive), the commands sent meanwhile reaching it 5 ms after: taken once
    the twin had simulated past them, the drive started late (6 cm short: the CI run beside two
    busy loops that found it had 2.3 cm); at their send times, as without the stall."""
    time.sleep(WATCHDOG_S + 0.1)  # at rest: stopped by its watchdog, no command flowing
    plain, plain_rest = _drive(child)
    time.sleep(WATCHDOG_S + 0.1)
    stalled, stalled_rest = _drive(child, tick_stall=(0.0, 0.3), late=True)
    print(f"the same drive: {plain:.4f} m, {stalled:.4f} m with the stall at its start (beyond "
          f"what was sent: {plain_rest * 1e3:+.1f}, {stalled_rest * 1e3:+.1f} mm)")  # fmt: skip
    assert plain > 0.15
    assert abs(stalled_rest - plain_rest) < 0.01, (plain, stalled, plain_rest, stalled_rest)


def test_a_stall_longer_than_the_watchdog_stops_the_twin_at_the_watchdog_time(
    child: subprocess.Popen[str],
) -> None:
    """The sender silent from 0.85 s to 2 s, the twin stopped over that span: stopped at the end
    of the stall, the twin drove on blind to it (14 cm further); by its watchdog at its time
    (0.5 s after the last command), within 1 cm of the same silence without a stall."""
    plain, plain_rest = _drive(child, silent=(0.85, 2.0), end_s=2.5)
    stalled, stalled_rest = _drive(child, stall=(0.85, 2.0), silent=(0.85, 2.0), end_s=2.5)
    print(f"the same silence: {plain:.4f} m, {stalled:.4f} m with the stall (beyond what was "
          f"sent: {plain_rest * 1e3:+.1f}, {stalled_rest * 1e3:+.1f} mm)")  # fmt: skip
    assert 0.15 < plain < 0.35  # moved, and stopped by the watchdog before the zero command
    assert abs(stalled_rest - plain_rest) < 0.01, (plain, stalled, plain_rest, stalled_rest)

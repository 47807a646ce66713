"""Progress displays of the long commands (rich.progress: imported only by the commands).

:func:`robot_time_progress` (a bar in robot seconds), :func:`campaign_progress` (a line per step).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, Protocol

from rich.progress import (
    BarColumn,
    Progress,
    ProgressColumn,
    SpinnerColumn,
    Task,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text

from omnical.cli.output import console

if TYPE_CHECKING:
    from omnical.web.tee import MonitorLink

__all__ = [
    "DistanceTally",
    "StepEvent",
    "campaign_progress",
    "count_progress",
    "robot_time_progress",
    "run_progress",
]


class StepEvent(Protocol):
    """What the campaign reports (:class:`omnical.calibration.campaign.CampaignProgress`)."""

    @property
    def step(self) -> str:
        """Name of the step (a run or an analysis)."""

    @property
    def done_s(self) -> float:
        """Robot time done in this step, s."""

    @property
    def total_s(self) -> float:
        """Robot time of this step, s (0: not a run)."""


@contextmanager
def robot_time_progress(label: str) -> Iterator[Callable[[float, float], None]]:
    """A bar ``label ━━━ done/total s robot time``; yields ``update(done_s, total_s)``."""
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} s robot time"),
        TimeRemainingColumn(),
        console=console(),
        transient=True,
        disable=not console().is_terminal,  # a log or a pipe: no bar, and no blank line
    ) as progress:
        task = progress.add_task(label, total=1.0)

        def update(done_s: float, total_s: float) -> None:
            progress.update(task, completed=done_s, total=max(total_s, 1e-9))

        yield update


class _RobotTimeColumn(ProgressColumn):
    """``done/total s robot time`` for a run, nothing for a step that is not a run."""

    def render(self, task: Task) -> Text:
        if task.total is None:
            return Text("")
        return Text(f"{task.completed:>5.0f}/{task.total:<5.0f} s robot time")


class _StepDisplay:
    """Turns step events into one progress line per step and a tick when a run is done."""

    def __init__(self, progress: Progress) -> None:
        self._progress = progress
        self._task: TaskID | None = None
        self._step = ""
        self._total_s = 0.0
        self._done_s = 0.0

    def __call__(self, event: StepEvent) -> None:
        if event.step != self._step:
            self._finish()
            self._step = event.step
            self._total_s = event.total_s
            self._done_s = 0.0
            total = event.total_s if event.total_s > 0.0 else None
            self._task = self._progress.add_task(event.step, total=total)
        if self._task is not None and event.total_s > 0.0:
            self._done_s = event.done_s
            self._progress.update(self._task, completed=event.done_s, total=event.total_s)

    def _finish(self, *, stopped: bool = False) -> None:
        if self._task is None:
            return
        if self._total_s > 0.0 and stopped:
            self._progress.console.print(
                f"[yellow]✗[/yellow] {self._step} stopped at {self._done_s:.0f} of "
                f"{self._total_s:.0f} s robot time"
            )
        elif self._total_s > 0.0:
            self._progress.console.print(
                f"[green]✓[/green] {self._step} ({self._total_s:.0f} s robot time)"
            )
        self._progress.remove_task(self._task)
        self._task = None

    def close(self, *, stopped: bool = False) -> None:
        """Tick the last step off, or say where it stopped (an error or an interruption)."""
        self._finish(stopped=stopped)


@contextmanager
def campaign_progress() -> Iterator[Callable[[StepEvent], None]]:
    """Yields the callback to hand to the campaign as its ``on_progress``."""
    with Progress(
        SpinnerColumn(),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        _RobotTimeColumn(),
        TimeElapsedColumn(),
        console=console(),
        transient=True,
    ) as progress:
        display = _StepDisplay(progress)
        try:
            yield display
        except BaseException:  # Ctrl-C, a safety stop: the step under way did not finish
            display.close(stopped=True)
            raise
        display.close()


@contextmanager
def count_progress(
    label: str, unit: str
) -> Iterator[tuple[Callable[[int, int], None], Callable[[int], None]]]:
    """A bar ``label ━━━ done/total UNIT`` for a fleet or a sweep; yields ``start(total, done)``
    (the jobs, and those a resume found done) and ``advance(n)``."""
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} " + unit),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console(),
        transient=True,
        disable=not console().is_terminal,  # a log or a pipe: no bar, and no blank line first
    ) as progress:
        task = progress.add_task(label, total=0)

        def start(total: int, done: int) -> None:
            progress.update(task, total=total, completed=done)

        def advance(n: int) -> None:
            progress.update(task, advance=n)

        yield start, advance


class DistanceTally:
    """A row sink in front of the run's: adds up the distance the odometry travelled;
    ``on_update(elapsed_s)`` (odometry time since its first row) after each batch of it."""

    def __init__(self, sink: Any, on_update: Callable[[float], None] | None = None) -> None:
        from omnical.recording.topics import ODOM

        self.sink = sink
        self.on_update = on_update
        self.distance_m = 0.0
        self._odom = ODOM
        self._last: tuple[float, float] | None = None
        self._t0_ns: int | None = None

    def write_rows(self, topic: str, t_ns: Any, **columns: Any) -> None:
        """Write through; on odometry rows, add the path length."""
        self.sink.write_rows(topic, t_ns, **columns)
        if topic != self._odom or "x_m" not in columns:
            return
        import numpy as np

        x = np.asarray(columns["x_m"], dtype=np.float64)
        y = np.asarray(columns["y_m"], dtype=np.float64)
        if len(x) == 0:
            return
        if self._last is not None:
            x, y = np.concatenate([[self._last[0]], x]), np.concatenate([[self._last[1]], y])
        step = np.hypot(np.diff(x), np.diff(y))
        self.distance_m += float(np.sum(step[np.isfinite(step)]))
        self._last = (float(x[-1]), float(y[-1]))
        t = np.asarray(t_ns, dtype=np.int64)
        if self._t0_ns is None:
            self._t0_ns = int(t[0])
        if self.on_update is not None:
            self.on_update((int(t[-1]) - self._t0_ns) / 1e9)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.sink, name)


class _RunColumn(ProgressColumn):
    """``12/40 s · 1.23 m · 28 s left`` (robot time; no total: elapsed and distance)."""

    def render(self, task: Task) -> Text:
        distance = task.fields.get("distance_m", 0.0)
        if task.total is None:
            return Text(f"{task.completed:>5.0f} s · {distance:.2f} m")
        left = max(task.total - task.completed, 0.0)
        return Text(
            f"{task.completed:>5.0f}/{task.total:<5.0f} s · {distance:.2f} m · {left:.0f} s left"
        )


@contextmanager
def run_progress(
    label: str, tally: DistanceTally | None = None, link: MonitorLink | None = None
) -> Iterator[Callable[[float, float], None]]:
    """A line ``label ━━━ done/total s · distance · time left`` (robot time) while the robot
    moves, the same sent to the monitor at most 5 times a second; yields ``update(done_s,
    total_s)`` (total 0: unknown)."""
    last = [0.0]
    unsent: list[dict[str, Any] | None] = [None]
    with Progress(
        SpinnerColumn(),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        _RunColumn(),
        console=console(),
        transient=True,
        disable=not console().is_terminal,  # a log or a pipe gets the lines after the run
    ) as progress:
        task = progress.add_task(label, total=None, distance_m=0.0)

        def update(done_s: float, total_s: float) -> None:
            distance = tally.distance_m if tally is not None else 0.0
            total = total_s if total_s > 0.0 and math.isfinite(total_s) else None
            progress.update(task, completed=done_s, total=total, distance_m=distance)
            now = time.monotonic()
            left = None if total is None else max(total - done_s, 0.0)
            figures = {"step": label, "done_s": done_s, "total_s": total_s, "left_s": left,
                       "distance_m": distance}  # fmt: skip
            unsent[0] = figures
            if link is not None and now - last[0] >= 0.2:
                last[0] = now
                link.send("progress", figures)
                unsent[0] = None

        try:
            yield update
        finally:  # the last figures, even when they came faster than 5 a second
            if link is not None and unsent[0] is not None:
                link.send("progress", unsent[0])

"""Progress displays of the long commands (rich.progress: imported only by the commands).

:func:`robot_time_progress` (a bar in robot seconds), :func:`campaign_progress` (a line per step).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol

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

__all__ = ["StepEvent", "campaign_progress", "count_progress", "robot_time_progress"]


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

    def __call__(self, event: StepEvent) -> None:
        if event.step != self._step:
            self._finish()
            self._step = event.step
            self._total_s = event.total_s
            total = event.total_s if event.total_s > 0.0 else None
            self._task = self._progress.add_task(event.step, total=total)
        if self._task is not None and event.total_s > 0.0:
            self._progress.update(self._task, completed=event.done_s, total=event.total_s)

    def _finish(self) -> None:
        if self._task is None:
            return
        if self._total_s > 0.0:
            self._progress.console.print(
                f"[green]✓[/green] {self._step} ({self._total_s:.0f} s robot time)"
            )
        self._progress.remove_task(self._task)
        self._task = None

    def close(self) -> None:
        """Tick the last step off."""
        self._finish()


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
        finally:
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
    ) as progress:
        task = progress.add_task(label, total=0)

        def start(total: int, done: int) -> None:
            progress.update(task, total=total, completed=done)

        def advance(n: int) -> None:
            progress.update(task, advance=n)

        yield start, advance

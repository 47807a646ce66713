"""The progress the monitor gets ends at the run's last figures, even when a run sent whole
(an in-process twin) updates it faster than the 5 frames a second it is thinned to (audit
item 5: the page showed step 1/80 s after the run)."""

from __future__ import annotations

from typing import Any

from omnical.cli.progress import run_progress


class _Heard:
    def __init__(self) -> None:
        self.frames: list[tuple[str, dict[str, Any]]] = []

    def send(self, stream: str, data: dict[str, Any]) -> None:
        self.frames.append((stream, dict(data)))


def test_the_last_progress_reaches_the_monitor() -> None:
    heard = _Heard()
    with run_progress("straight-10m", None, heard) as update:  # type: ignore[arg-type]
        for k in range(1, 81):
            update(float(k), 80.0)  # 80 robot seconds within a few milliseconds
    assert 1 <= len(heard.frames) <= 3
    assert heard.frames[0][1]["done_s"] == 1.0
    assert heard.frames[-1] == (
        "progress",
        {"step": "straight-10m", "done_s": 80.0, "total_s": 80.0, "left_s": 0.0, "distance_m": 0.0},
    )

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


def test_a_stopped_step_is_logged_as_aborted_not_ended() -> None:
    """Audit item 8: the move a user stopped was logged as a normal ``move end``."""
    import json

    from omnical.experiment.runner import run_script
    from omnical.experiment.script import load_script
    from omnical.robot.loader import load_robot
    from omnical.twin.clock import TwinClock
    from omnical.twin.params import TwinParams
    from omnical.twin.simulator import DigitalTwin
    from omnical.web.protocol import event_payload

    robot = load_robot("rosy-mecanum")
    twin = DigitalTwin(robot, TwinParams.ideal_twin(), seed=0)

    def stopping(elapsed_s: float, total_s: float) -> None:
        del total_s
        if elapsed_s > 5.0:  # within step 2 (the move), as a q would
            raise KeyboardInterrupt

    log = run_script(
        load_script("straight-10m", robot.limits), twin, TwinClock(twin), on_tick=stopping
    )
    assert log.interrupted
    texts = [text for _, text in log.events]
    assert [json.loads(t)["edge"] for t in texts] == ["start", "end", "start", "aborted"]
    shown = event_payload(0.0, texts[-1])
    assert shown["level"] == "abort" and shown["text"].endswith("step 2 move aborted (forward)")

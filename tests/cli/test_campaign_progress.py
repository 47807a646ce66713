"""The campaign's progress lines: a step is ticked off when it finished, and a step an
interruption or a safety stop ended says where it stopped (a new user saw "✓ iteration 1:
rotation procedure (63 s robot time)" above a run kept as ``iter1-rotation-stopped``)."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from omnical.cli.progress import campaign_progress


@dataclass(frozen=True)
class _Step:
    step: str
    done_s: float
    total_s: float


@pytest.fixture(autouse=True)
def _plain_output(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("FORCE_COLOR", "TTY_COMPATIBLE", "TTY_INTERACTIVE"):  # rich's: a terminal
        monkeypatch.delenv(name, raising=False)


def test_finished_steps_are_ticked_off(capsys: pytest.CaptureFixture[str]) -> None:
    with campaign_progress() as on_progress:
        on_progress(_Step("iteration 1: rotation procedure", 63.0, 63.0))
        on_progress(_Step("iteration 1: analysis", 0.0, 0.0))  # not a run: no line
        on_progress(_Step("iteration 1: longitudinal procedure", 40.0, 40.0))
    out = [line for line in capsys.readouterr().out.splitlines() if line]
    assert out == [
        "✓ iteration 1: rotation procedure (63 s robot time)",
        "✓ iteration 1: longitudinal procedure (40 s robot time)",
    ]


def test_a_stopped_step_says_where_it_stopped(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(KeyboardInterrupt), campaign_progress() as on_progress:
        on_progress(_Step("iteration 1: rotation procedure", 63.0, 63.0))
        on_progress(_Step("iteration 1: lateral procedure", 10.0, 50.0))
        on_progress(_Step("iteration 1: lateral procedure", 32.4, 50.0))
        raise KeyboardInterrupt
    out = [line for line in capsys.readouterr().out.splitlines() if line]
    assert out == [
        "✓ iteration 1: rotation procedure (63 s robot time)",
        "✗ iteration 1: lateral procedure stopped at 32 of 50 s robot time",
    ]

"""``held_stops``: a stop during a swap decides it once; a stop after the swap began is late."""

from __future__ import annotations

import os
import signal

import pytest

from omnical.recording.staging import held_stops


def test_a_stop_before_the_decision_is_raised_after_the_block() -> None:
    with pytest.raises(KeyboardInterrupt), held_stops() as stopped:
        os.kill(os.getpid(), signal.SIGINT)
        assert stopped()  # the block keeps the earlier output; the stop comes at its end


def test_a_stop_after_the_block_went_on_is_said_and_not_raised(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The fresh-eyes rerun of issue 28: a stop in the ~10 ms while the earlier output was
    removed exited 130 with the new output already in place and no "wrote" line."""
    with held_stops() as stopped:
        assert not stopped()  # no stop: the new output goes in place
        os.kill(os.getpid(), signal.SIGINT)  # ... and one comes while it does
    assert "complete and kept; nothing left to stop" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored

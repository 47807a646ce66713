"""``held_stops``: a stop during a swap decides it once; a stop after the swap began is late."""

from __future__ import annotations

import os
import signal
import sys

import pytest
import typer

from omnical.bags.staging import held_stops


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


def test_a_stop_after_the_output_is_in_place_lets_the_command_finish(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The same rerun: a stop in the few ms after the swap, while the command printed what it
    wrote, exited 130 with the new output in place. Now the command finishes, exit 0."""
    from omnical.cli.errors import handled_errors, install_signal_handlers

    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    saved_hook = sys.unraisablehook
    try:
        install_signal_handlers()
        finished = False
        with handled_errors():
            with held_stops() as stopped:
                assert not stopped()  # the output goes in place
            os.kill(os.getpid(), signal.SIGTERM)  # ... then a stop, while "wrote ..." is said
            finished = True
        assert finished
        assert "the stop came after the output was in place" in capsys.readouterr().err
        with pytest.raises(typer.Exit) as stop, handled_errors():  # the next command: not late
            os.kill(os.getpid(), signal.SIGTERM)
        assert stop.value.exit_code == 143
    finally:
        for s, handler in saved.items():
            signal.signal(s, handler)
        sys.unraisablehook = saved_hook

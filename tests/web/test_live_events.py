"""A run's step events reach the page as they happen (issue 26): ``twin serve --monitor`` prints
the command to run against it, which is run as printed; each step marker is on the page while
the run still goes, once, with its run time in the page's one format (``t+12.3 s``)."""

from __future__ import annotations

import re
import signal
from pathlib import Path
from typing import Any

import pytest
from monitor_procs import Monitor, figures, new_page, start, wait_until

_SCRIPT = """name: live-steps
steps:
  - hold: {duration_s: 0.5, marker: settle}
  - move: {vx_mps: 0.1, duration_s: 1.5, marker: first}
  - move: {vy_mps: 0.1, duration_s: 5.0, marker: second}
"""


@pytest.mark.alone
def test_steps_are_on_the_page_while_the_run_goes(
    monitor: Monitor, browser: Any, tmp_path: Path
) -> None:
    served = start("twin", "serve", "--time-scale", "2", "--monitor", str(monitor.port))
    try:
        hint = served.wait_for(r"^\s+omnical run SCRIPT .*").group(0).split()
        assert hint[hint.index("--beacons") + 1] == "default"
        assert hint[hint.index("--time-scale") + 1] == "2"  # the server's clock, or no run
        assert hint[hint.index("--monitor") + 1] == str(monitor.port)
        script = tmp_path / "live-steps.yaml"
        script.write_text(_SCRIPT)
        args = [str(script) if a == "SCRIPT" else a for a in hint[2:]]  # as printed
        args = [str(tmp_path / "r.mcap") if a == "RUN.mcap" else a for a in args]
        page, errors = new_page(browser, monitor.url)
        wait_until(page, "m.connected", 10)
        run = start("run", *args, "--yes")
        # the last step starts 1 s (wall) into the script and lasts 2.5 s: seen before the end
        wait_until(page, "document.getElementById('log').innerText.includes('step 3 move start')",
                   30)  # fmt: skip
        assert run.popen.poll() is None, "the step came only when the run ended"
        log_then = page.inner_text("#log")
        assert "live-steps: step 2 move start (first)" in log_then
        assert "step 3 move end" not in log_then  # (the recorded markers come all at once)
        assert run.popen.wait(60) == 0, run.popen.stderr.read() if run.popen.stderr else ""
        wait_until(page, "m.state.clock && m.state.clock.end !== null", 10)  # the run is over
        log = page.inner_text("#log")
        assert log.count("step 3 move start") == 1  # the recorded markers are not sent again
        assert "step 3 move end (second)" in log
        stamps = page.locator("#log li .t").all_inner_texts()
        assert stamps and all(re.fullmatch(r"t[+−]\d+\.\d s", s) for s in stamps), stamps
        assert re.fullmatch(r"t\+\d+\.\d s", page.inner_text("#runtime"))
        assert errors == [] and figures(page)["errors"] == []
    finally:
        assert served.stop(signal.SIGINT) == 130

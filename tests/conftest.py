"""Suite-wide settings: hypothesis runs derandomised on CI (the same examples every run, so a
red CI is a real regression), randomised on a developer's machine (new examples each run).

One BLAS thread per process (unless the environment says otherwise): the suite runs a process
per core (xdist) and the omnical subprocesses of the CLI tests beside them, and OpenBLAS's own
threads, one per core in every process, spin waiting for work on cores that are all busy.
Measured on 2 cores under load: two joint-calibration tests took 13.9 s of CPU with them,
4.0 s without. (A thread count changes at most the order of a BLAS sum: rounding far below any
tolerance here.) Set before anything imports numpy; the subprocesses inherit it.

The order of the test files: ``make test`` hands whole files to the workers (``--dist loadfile
--no-loadscope-reorder``) in collection order, so the files that take the most CPU come first
(longest first: a worker that gets a 40-second file last keeps the run waiting for it alone).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

# A suite started as a background job (`make test &` in a script) inherits SIGINT ignored, and so
# would every omnical process the tests start: the Ctrl-C tests would see Ctrl-C do nothing.
# A handler (unlike "ignored") is not inherited across exec: the children get the default.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

import functools  # noqa: E402

import pytest  # noqa: E402
import typer.testing  # noqa: E402
from hypothesis import settings  # noqa: E402

# `CliRunner().invoke(app, …)` builds the app's whole click command tree again on every call
# (typer reads every command's signature and evaluates its annotations): 20 ms a call, ≈ 475
# calls in the suite, 9.5 s of CPU. The tree is the same each time (a click command keeps no
# state between invocations): one per app and process. (A user's `omnical` builds it once.)
typer.testing._get_command = functools.cache(typer.testing._get_command)

settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

# The files with the most CPU time, most first (measured with OMNICAL_TEST_CPU_LOG, below: seconds
# of CPU per file, its subprocesses included, in the parallel suite with warm caches (bytecode and
# numba's: a cold run compiles, and ranked navigation/test_planning.py at 5.9 s, 0.3 s warm) at
# load 3-5 from other work, issue 24 session 15); every other file keeps its place. A name missing
# here only loses its head start; a heavy file left to the end keeps the run waiting for it alone.
HEAVY_FIRST = (
    "web/test_browser.py",  # 18 s: chromium
    "test_demo.py",  # 15 s: the demo once (with its navigation chapter), its report once
    "calibration/test_joint_noise.py",  # 10 s: twenty random robots' tours
    "recording/test_export_stream.py",  # 9.4 s
    "fleet/test_fleet_cli.py",  # 9.0 s (and its pool's processes)
    "cli/test_evaluate_reference_cli.py",  # 7.6 s
    "cli/test_signals.py",  # 7.1 s
    "cli/test_navigation_cli.py",  # 7.0 s
    "fleet/test_fleet_references.py",  # 6.6 s
    "calibration/test_joint.py",  # 6.5 s
    "calibration/test_joint_long.py",  # 6.5 s
    "estimation/test_smoother_scale.py",  # 6.0 s
    "cli/test_reference_cli.py",  # 5.8 s
    "cli/test_interruptions.py",  # 5.7 s
    "fleet/test_sweep.py",  # 5.6 s (and its pools' and Dask worker's processes)
    "calibration/test_campaign.py",  # 5.5 s
    "estimation/test_smoother_keyframes.py",  # 5.4 s
    "cli/test_calibrate_cli.py",  # 5.3 s
    "evaluation/test_smoothed.py",  # 4.8 s
    "evaluation/test_lean.py",  # 4.3 s
    "cli/test_campaign_interruptions.py",  # 4.2 s
    "evaluation/test_track_recording.py",  # 3.5 s
    "cli/test_cli.py",  # 3.5 s
    "cli/test_locate_outputs_cli.py",  # 3.2 s
    "estimation/test_se2.py",  # 3.0 s
    "test_userfiles.py",  # 2.9 s
)


def _heavy_rank(item: pytest.Item) -> int:
    path = item.path.as_posix()
    for rank, name in enumerate(HEAVY_FIRST):
        if path.endswith("/tests/" + name):
            return rank
    return len(HEAVY_FIRST)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    items.sort(key=_heavy_rank)  # stable: within a file and among the rest, collection order
    # `make test`'s alone sessions collect only the files with "mark.alone" written in them
    # (Makefile, ALONE_FILES) and the parallel suite deselects `alone`: a test marked another
    # way would run in neither
    texts: dict[Path, bool] = {}
    for item in items:
        if item.get_closest_marker("alone") is not None:
            if item.path not in texts:
                texts[item.path] = "mark.alone" in item.path.read_text(encoding="utf-8")
            if not texts[item.path]:
                msg = f"{item.nodeid}: marked alone without 'mark.alone' written in its file"
                raise pytest.UsageError(msg)


# `OMNICAL_TEST_CPU_LOG=FILE pytest ...` appends one line per test to FILE: CPU seconds (the
# test process's and its finished subprocesses', module fixtures counted where first used),
# wall seconds, node id. CPU is what a loaded machine cannot inflate: rank tests by it.
_CPU_LOG = os.environ.get("OMNICAL_TEST_CPU_LOG")


def _cpu_s() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


if _CPU_LOG:

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> object:
        cpu, wall = _cpu_s(), time.perf_counter()
        yield
        line = f"{_cpu_s() - cpu:.3f}\t{time.perf_counter() - wall:.3f}\t{item.nodeid}\n"
        with Path(_CPU_LOG).open("a", encoding="utf-8") as log:
            log.write(line)

"""The executors: the ``--executor`` forms, the one line when the cluster extra is missing, and
the same answers from each executor (issue 27)."""

from __future__ import annotations

import signal
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from typing import ClassVar

import pytest

from omnical.errors import ConfigError
from omnical.fleet.executors import ExecutorSpec, open_executor, parse_executor
from omnical.fleet.runner import auto_chunk


def test_executor_forms() -> None:
    assert parse_executor("serial") == ExecutorSpec("serial")
    assert parse_executor("local:3") == ExecutorSpec("local", 3)
    assert parse_executor("local").workers >= 1
    assert parse_executor("dask-local:2") == ExecutorSpec("dask-local", 2)
    spec = parse_executor("dask://127.0.0.1:8786")
    assert spec == ExecutorSpec("dask", 0, "tcp://127.0.0.1:8786")
    assert str(spec) == "dask://127.0.0.1:8786"


@pytest.mark.parametrize(
    "text", ["ray", "local:0", "local:x", "dask-local", "dask://host", "dask://h:70000", ""]
)
def test_bad_executor_is_one_line(text: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_executor(text)
    assert "\n" not in str(err.value)
    assert "--executor" in str(err.value)


def test_missing_cluster_extra_names_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed fails
    with (
        pytest.raises(ConfigError, match=r"pip install 'omnical\[cluster\]'"),
        open_executor(parse_executor("dask-local:1")),
    ):
        pass


def _square(x: int) -> int:
    return x * x


def test_serial_and_local_answer_alike() -> None:
    for text in ("serial", "local:2"):
        with open_executor(parse_executor(text)) as pool:
            assert list(pool.map(_square, range(5))) == [0, 1, 4, 9, 16]


def test_auto_chunk_keeps_eight_tasks_per_worker_at_most_four_jobs() -> None:
    assert auto_chunk(1000, 2) == 4
    assert auto_chunk(20, 2) == 2
    assert auto_chunk(3, 4) == 1


class _Pool314(ProcessPoolExecutor):
    """A pool with Python 3.14's ``terminate_workers`` (as 3.14 does it), on older Pythons."""

    ended: ClassVar[list[int]] = []

    def terminate_workers(self) -> None:
        workers = list((self._processes or {}).values())
        self.shutdown(wait=False, cancel_futures=True)
        for worker in workers:
            worker.terminate()
        type(self).ended.append(len(workers))


@pytest.mark.parametrize("python", ["3.14", "before 3.14"])
def test_a_stop_ends_the_running_workers(monkeypatch: pytest.MonkeyPatch, python: str) -> None:
    import omnical.fleet.executors as executors

    if python == "3.14":
        monkeypatch.setattr(executors, "ProcessPoolExecutor", _Pool314)
    _Pool314.ended.clear()
    with pytest.raises(KeyboardInterrupt), open_executor(parse_executor("local:1")) as pool:
        running = pool.submit(time.sleep, 600)  # a job that runs until it is stopped
        workers = list(getattr(pool, "_processes", {}).values())
        while not running.running():
            time.sleep(0.01)
        raise KeyboardInterrupt
    assert _Pool314.ended == (
        [1] if python == "3.14" else []
    )  # its terminate_workers, when it has one
    (worker,) = workers
    worker.join(timeout=10.0)
    # ended, not finished: SIGTERM's status, or 255 from a worker still starting up when it
    # came (once beside two busy loops: its future is "running" once queued to the worker)
    assert not worker.is_alive() and worker.exitcode in (-signal.SIGTERM, 255), worker.exitcode

"""Executors behind ``concurrent.futures.Executor``: ``serial``, ``local[:N]``, ``dask-local:N``,
``dask://HOST:PORT``. Dask is imported here only, and only when one of its executors is asked for.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from contextlib import AbstractContextManager, ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any, Final, ParamSpec, TypeVar

from omnical.errors import ConfigError

__all__ = [
    "CLUSTER_EXTRA",
    "DASK_CONNECT_TIMEOUT_S",
    "DASK_WORKER_CONFIG",
    "ExecutorSpec",
    "SerialExecutor",
    "open_executor",
    "parse_executor",
    "task_wanted",
]

CLUSTER_EXTRA: Final = "pip install 'omnical[cluster]'"
"""How to install what the Dask executors need (``dask[distributed]``)."""

DASK_CONNECT_TIMEOUT_S: Final = 10.0
"""How long ``dask://HOST:PORT`` waits for its scheduler before saying it is not there."""

DASK_WORKER_CONFIG: Final = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.gil.enabled": False,
}
"""Dask settings of the ``dask-local`` workers (for a cluster of your own: the README)."""

_P = ParamSpec("_P")
_T = TypeVar("_T")

_SPEC = re.compile(r"^(serial|local|local:(\d+)|dask-local:(\d+)|dask://([^:/\s]+):(\d+))$")


@dataclass(frozen=True)
class ExecutorSpec:
    """A parsed ``--executor``.

    Attributes:
        kind: ``serial`` (this process), ``local`` (processes), ``dask-local`` (a Dask
            LocalCluster of processes) or ``dask`` (a running Dask scheduler).
        workers: worker processes (``local``, ``dask-local``); 0 for the others.
        address: ``tcp://HOST:PORT`` of the scheduler (``dask``), else "".
    """

    kind: str
    workers: int = 0
    address: str = ""

    def __str__(self) -> str:
        if self.kind == "dask":
            return "dask://" + self.address.removeprefix("tcp://")
        return f"{self.kind}:{self.workers}" if self.workers else self.kind


def parse_executor(text: str) -> ExecutorSpec:
    """``--executor`` as an :class:`ExecutorSpec`.

    Raises:
        ConfigError: not one of the forms, or a count of 0 workers or a port out of range.
    """
    match = _SPEC.match(text.strip())
    forms = "serial, local, local:N, dask-local:N or dask://HOST:PORT"
    if match is None:
        raise ConfigError(f"--executor {text!r}: expected {forms}")
    whole, local_n, dask_n, host, port = match.groups()
    if whole == "serial":
        return ExecutorSpec("serial")
    if whole == "local":
        return ExecutorSpec("local", os.cpu_count() or 1)
    if local_n is not None or dask_n is not None:
        n = int(local_n if local_n is not None else dask_n)
        if not 1 <= n <= 1024:
            raise ConfigError(f"--executor {text!r}: the number of workers must be 1 to 1024")
        return ExecutorSpec("local" if local_n is not None else "dask-local", n)
    if not 1 <= int(port) <= 65535:
        raise ConfigError(f"--executor {text!r}: port {port} is not 1 to 65535")
    return ExecutorSpec("dask", 0, f"tcp://{host}:{int(port)}")


class SerialExecutor(Executor):
    """Runs each task in this process when it is submitted (the baseline, and debugging)."""

    def submit(self, fn: Callable[_P, _T], /, *args: _P.args, **kwargs: _P.kwargs) -> Future[_T]:
        future: Future[_T] = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except BaseException as err:
            if isinstance(err, KeyboardInterrupt | SystemExit):
                raise
            future.set_exception(err)
        return future


@contextmanager
def open_executor(spec: ExecutorSpec) -> Iterator[Executor]:
    """The executor ``spec`` names, shut down (and its cluster closed) when the block ends.

    Raises:
        ConfigError: a Dask executor without ``dask[distributed]`` installed (the line says
            how to install it), or a scheduler that does not answer.
    """
    if spec.kind == "serial":
        yield SerialExecutor()
        return
    if spec.kind == "local":
        import multiprocessing

        # forkserver: workers start from a clean process, not a copy of one with threads (the
        # progress display's) and whatever this one imported.
        context = multiprocessing.get_context("forkserver")
        # Ctrl-C reaches the workers too (one process group): it is the coordinator's to
        # handle; an idle worker's own KeyboardInterrupt printed a traceback each
        pool = ProcessPoolExecutor(spec.workers, mp_context=context, initializer=_ignore_sigint)
        try:
            yield pool
        except BaseException:
            _stop_pool(pool)
            raise
        pool.shutdown(wait=True)
        return
    with ExitStack() as stack:
        yield stack.enter_context(_dask_executor(spec))


def _ignore_sigint() -> None:
    """In a ``local`` or ``dask-local`` worker: Ctrl-C is the coordinator's to handle."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _stop_pool(pool: ProcessPoolExecutor) -> None:
    """A stop (Ctrl-C, SIGTERM, an error): the jobs not started cancelled, and the workers
    ended without waiting for the jobs they run (whose rows are not written: ``--resume``)."""
    terminate = getattr(pool, "terminate_workers", None)
    if callable(terminate):
        # Python 3.14 and later: the public call (it shuts the pool down without waiting,
        # cancelling what has not started, then sends each worker SIGTERM); the shutdown
        # after it waits for nothing but is the same last step as below
        terminate()
        pool.shutdown(wait=True, cancel_futures=True)
        return
    # Before 3.14 there is no public way to the workers: the fallback reads the pool's private
    # _processes and manager thread. First the shutdown that cancels what has not started: the
    # manager thread cancels and drops those jobs before it can next see a worker gone, since
    # it reads its wake-up before the workers' ends and checks the shutdown after every result.
    # (The runner leaves their cancelling to it: a job cancelled elsewhere that the thread then
    # failed, its workers or forkserver dead first, as on a SIGTERM to the process group, was
    # on 3.11 "Exception in thread ... InvalidStateError: CANCELLED" after "omnical:
    # terminated".) Then the workers are ended, and the manager
    # thread, which sees them gone and fails what ran, is joined here, not in the interpreter's
    # exit, where its wake-up pipe raced its closing ("Exception ignored in threading ... Bad
    # file descriptor" after "omnical: terminated")
    workers = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for worker in workers:
        worker.terminate()
    for worker in workers:
        worker.join(timeout=5.0)
        if worker.is_alive():  # pragma: no cover - a worker that ignores SIGTERM
            worker.kill()
    if manager is not None:
        manager.join(timeout=10.0)
    pool.shutdown(wait=True)


def task_wanted() -> bool:
    """Whether the task this thread runs is still wanted: False only in a Dask worker whose
    scheduler cancelled it (a stop: Dask cannot interrupt a running task, so a chunk checks
    this before each of its jobs and starts no more). True anywhere else."""
    import sys

    distributed = sys.modules.get("distributed")  # a Dask worker has it loaded; a pool's not
    if distributed is None:
        return True
    try:
        worker = distributed.get_worker()
    except ValueError:  # not in a Dask worker's task
        return True
    key = worker.get_current_task()
    if key is None:
        return True
    task = worker.state.tasks.get(key)  # a cancelled task that still runs: "cancelled"
    return task is not None and task.state != "cancelled"


def _distributed() -> Any:
    """The ``distributed`` module, or the one-line error naming the extra."""
    try:
        import distributed
    except ImportError:
        msg = f"the Dask executors need dask[distributed]: {CLUSTER_EXTRA}"
        raise ConfigError(msg) from None
    return distributed


def _dask_executor(spec: ExecutorSpec) -> AbstractContextManager[Executor]:
    distributed = _distributed()

    @contextmanager
    def opened() -> Iterator[Executor]:
        import dask

        with ExitStack() as stack:
            if spec.kind == "dask-local":
                # no statistical profiler in the workers: sampling the task's stack takes the
                # GIL from it (docs/DESIGN-NOTES.md, fleet)
                stack.enter_context(dask.config.set(DASK_WORKER_CONFIG))
                cluster = stack.enter_context(
                    distributed.LocalCluster(
                        n_workers=spec.workers,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=None,  # no web dashboard
                        # the scheduler's HTTP routes (health, metrics) on a free loopback port:
                        # by default all interfaces, port 8787 (two sweeps at once: a warning)
                        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                        silence_logs=40,  # logging.ERROR: no worker chatter on the terminal
                    )
                )
                client = stack.enter_context(distributed.Client(cluster))
                # Ctrl-C reaches the workers too (one process group): the coordinator stops
                # them when it closes the cluster; their own KeyboardInterrupt printed a
                # traceback each
                client.run(_ignore_sigint)
            else:
                try:
                    client = distributed.Client(
                        spec.address, timeout=DASK_CONNECT_TIMEOUT_S, set_as_default=False
                    )
                except OSError as err:  # TimeoutError, refused: one line, no traceback
                    msg = (
                        f"--executor {spec}: no Dask scheduler answered at {spec.address} "
                        f"within {DASK_CONNECT_TIMEOUT_S:g} s ({type(err).__name__})"
                    )
                    raise ConfigError(msg) from None
                stack.enter_context(client)
            executor: Executor = client.get_executor(pure=False)
            try:
                yield executor
            except BaseException:
                # a stop (Ctrl-C, SIGTERM, an error): every task of this run cancelled on the
                # scheduler before the client goes (Dask's executor cancels its futures when
                # shut down without waiting): a queued one never runs. A task already running
                # in a worker's thread cannot be interrupted: it ends on its own, its result
                # dropped (no row; ``--resume`` runs it again)
                executor.shutdown(wait=False)
                raise

    return opened()

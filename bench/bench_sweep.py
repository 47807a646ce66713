"""Sweep benchmark (issue 27): ``--runs`` (1000) short twin campaigns (one iteration, no
validation) on ``local:N`` and on ``dask-local:N``; each executor's overhead as a share of the
work.

Measured in this process, one after the other: the executor's start (pool or LocalCluster),
then the runs (``run_jobs`` with the chunking ``omnical sweep`` chooses, rows written to a
table as they complete). The work is the time the workers spent inside the chunks (each chunk
timed in its worker); the overhead = (N × the run's wall time − the work) / the work: the
workers' time not spent on campaigns (dispatch, results, the last chunks' tail), which the
machine's other load does not inflate the way it does a wall-time comparison (on a loaded
machine the same chunk's time varied 2× between repeats). Target for Dask: ≤ 2 %. The tables
(and a serial run of the first ``--serial-runs`` campaigns) are compared.

``python bench/bench_sweep.py [--runs 1000] [--workers 2] [--serial-runs 50] [--chunk 0]
[--repeats 1]`` (repeats interleave local and Dask).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

SPEC = """\
twin: default
iterations: 1
parameters:
  true_factors.scale.lateral: {uniform: [1.05, 1.2]}
  ips.distance_noise_m: {loguniform: [0.005, 0.03]}
  ips.nlos_probability: {choice: [0.0, 0.05, 0.1]}
"""


def timed_chunk(jobs: list[Any]) -> list[dict[str, str]]:
    """A sweep chunk, its time inside the worker in its first row (not a column: not written)."""
    from omnical.fleet.sweep import run_sweep_chunk

    start = time.perf_counter()
    rows = run_sweep_chunk(jobs)
    rows[0]["_inside_s"] = repr(time.perf_counter() - start)
    return rows


def _run(executor: str, runs: int, chunk: int, out: Path) -> tuple[float, float, float, str]:
    """Start, run, work inside the workers and the table of ``runs`` campaigns on ``executor``."""
    from omnical.fleet.executors import open_executor, parse_executor
    from omnical.fleet.runner import auto_chunk, run_jobs
    from omnical.fleet.sweep import SweepJob, parse_sweep_spec, sweep_header
    from omnical.fleet.table import ResultsTable
    from omnical.userfiles import parse_yaml

    spec = parse_sweep_spec(parse_yaml(SPEC, "bench"), "bench", SPEC)
    spec_exec = parse_executor(executor)
    workers = spec_exec.workers or 1
    out.mkdir(parents=True, exist_ok=True)
    inside = [0.0]

    class Table(ResultsTable):
        def append(self, rows: Iterable[Mapping[str, str]]) -> None:
            rows = list(rows)
            inside[0] += sum(float(r.get("_inside_s", 0.0)) for r in rows)
            super().append(rows)

    table = Table(out / "sweep.csv", sweep_header(spec), resume=False)
    jobs = [SweepJob(i, 2027, spec) for i in range(runs)]

    def failed(job: SweepJob, reason: str) -> dict[str, str]:
        return {"index": str(job.index), "status": "error", "reason": reason}

    t0 = time.perf_counter()
    with open_executor(spec_exec) as pool:
        t1 = time.perf_counter()
        run_jobs(
            pool,
            timed_chunk,
            jobs,
            table,
            chunk=chunk or auto_chunk(runs, workers),
            in_flight=2 * workers,
            failed=failed,
        )
        t2 = time.perf_counter()
    rows = table.close(sort=True)
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"{len(bad)} runs failed: {bad[0]['reason']}")
    return t1 - t0, t2 - t1, inside[0], (out / "sweep.csv").read_text()


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--serial-runs", type=int, default=50)
    parser.add_argument("--chunk", type=int, default=0)
    parser.add_argument("--repeats", type=int, default=1)
    args = parser.parse_args(argv)
    n, w = args.runs, args.workers
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        _, serial_s, _, serial_table = _run("serial", args.serial_runs, 1, folder / "serial")
        per_run = serial_s / args.serial_runs
        print(f"sweep: {n} campaigns (one iteration, no validation), {w} workers")
        print(f"  serial: {per_run * 1e3:.0f} ms per campaign ({args.serial_runs} runs)")
        results: dict[str, str] = {}
        overheads: dict[str, list[float]] = {}
        for _ in range(args.repeats):  # interleaved: the machine's load falls on both alike
            for executor in (f"local:{w}", f"dask-local:{w}"):
                start, run, work, table = _run(executor, n, args.chunk, folder / executor)
                results[executor] = table
                overhead = (w * run - work) / work
                overheads.setdefault(executor, []).append(overhead)
                print(
                    f"  {executor:13s} start {start:5.2f} s  runs {run:7.1f} s  work {work:7.1f} s "
                    f"({1e3 * work / n:.0f} ms per campaign)  overhead {100 * overhead:5.2f} % "
                    f"of the work; {n / run:.1f} campaigns/s (serial {1 / per_run:.1f})"
                )
        for executor, values in overheads.items():
            print(
                f"  {executor}: overhead median {100 * statistics.median(values):.2f} % of the work"
            )
        local, dask = results[f"local:{w}"], results[f"dask-local:{w}"]
        head = len(serial_table.splitlines())
        same = local == dask and local.splitlines()[:head] == serial_table.splitlines()
        print(f"  tables identical (local, Dask, serial's first {head - 1} rows): {same}")
        print(f"  load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main(sys.argv[1:])

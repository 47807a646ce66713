"""Fleet benchmark (issue 27): ``fleet calibrate`` throughput on ``local:N`` against serial, and
the coordinating process's memory against the number of recordings.

* Throughput: ``--recordings`` (100) twin recordings of ``--minutes`` (10) minutes (the tour's
  80-s loop repeated, ``omnical simulate``; ``--distinct`` (4) different seeds, listed over and
  over) calibrated one by one in this process (``serial``, the baseline) and on ``local:N``
  (the pool's start included), one after the other in this process, ``--repeats`` times
  interleaved (the shortest of each kept); the ratio serial / local.
  The target: ≥ 1.8× on a quiet 2-core machine. Then ``local:N`` once more, each job timed in
  its worker: the pool's overhead as a share of the work (``bench_sweep.py``'s measure, which
  the machine's other load does not inflate the way it does a wall-time ratio).
* Memory: ``fleet locate`` of a 1-minute recording listed ``--counts`` times (10 100 1000) on
  ``local:N``, each in a fresh process: the coordinator's peak (VmHWM; the workers are other
  processes), flat when the coordinator holds only the chunks in flight.

``python bench/bench_fleet.py [--recordings 100] [--minutes 10] [--workers 2] [--counts ...]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

LOOP = [
    "  - hold: {duration_s: 3.0}",
    "  - move: {vx_mps: 0.25, distance_m: 2.5}",
    "  - hold: {duration_s: 2.0}",
    "  - move: {vy_mps: 0.2, distance_m: 2.0}",
    "  - hold: {duration_s: 2.0}",
    "  - move: {wz_radps: 0.8, angle_deg: 1080}",
    "  - hold: {duration_s: 2.0}",
    "  - move: {vx_mps: -0.25, distance_m: 2.5}",
    "  - hold: {duration_s: 2.0}",
    "  - move: {vy_mps: -0.2, distance_m: 2.0}",
    "  - hold: {duration_s: 3.0}",
]


def simulated(folder: Path, minutes: float, seeds: range) -> list[Path]:
    """Twin recordings of about ``minutes`` minutes, one per seed (``omnical simulate``)."""
    loops = max(1, round(60 * minutes / 80))
    script = folder / f"loop{loops}.yaml"
    script.write_text("name: long\nsteps:\n" + "\n".join(LOOP * loops) + "\n")
    omnical = Path(sys.executable).with_name("omnical")
    bags = []
    for seed in seeds:
        bag = folder / f"m{minutes:g}-s{seed}.mcap"
        if not bag.with_suffix("").exists():
            args = [str(omnical), "simulate", str(script), "--seed", str(seed), "--out", str(bag)]
            subprocess.run(args, check=True, capture_output=True)
        bags.append(bag.with_suffix(""))
    return bags


def _vmhwm_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1000.0
    return float("nan")


def _fleet(bags: list[Path], command: str, executor: str, out: Path) -> float:
    from omnical.fleet.executors import parse_executor
    from omnical.fleet.jobs import FleetOptions
    from omnical.fleet.recordings import run_fleet

    start = time.perf_counter()
    result = run_fleet(bags, FleetOptions(command), parse_executor(executor), out, overwrite=True)
    wall = time.perf_counter() - start
    bad = [r for r in result.rows if r["status"] != "ok"]
    if bad:
        raise SystemExit(f"{len(bad)} recordings failed: {bad[0]['reason']}")
    return wall


def timed_fleet_chunk(jobs: list[Any]) -> list[dict[str, str]]:
    """A fleet chunk, its time inside the worker in its first row (not a column: not written)."""
    from omnical.fleet.jobs import run_fleet_chunk

    start = time.perf_counter()
    rows = run_fleet_chunk(jobs)
    rows[0]["_inside_s"] = repr(time.perf_counter() - start)
    return rows


def pool_overhead(bags: list[Path], workers: int, out: Path) -> float:
    """The pool's overhead as a share of the work (``bench_sweep.py``'s measure): the workers'
    time not spent inside the jobs, the pool's start included, over the time inside them."""
    from collections.abc import Iterable, Mapping

    from omnical.fleet.executors import open_executor, parse_executor
    from omnical.fleet.jobs import FleetJob, FleetOptions, error_row, fleet_header
    from omnical.fleet.runner import run_jobs
    from omnical.fleet.table import ResultsTable

    inside = [0.0]

    class Table(ResultsTable):
        def append(self, rows: Iterable[Mapping[str, str]]) -> None:
            rows = list(rows)
            inside[0] += sum(float(r.get("_inside_s", 0.0)) for r in rows)
            super().append(rows)

    out.mkdir(parents=True, exist_ok=True)
    table = Table(out / "fleet.csv", fleet_header("calibrate"), resume=False)
    options = FleetOptions("calibrate")
    jobs = [
        FleetJob(i, str(b), f"r{i}", str(out / "recordings" / f"r{i}"), options)
        for i, b in enumerate(bags)
    ]
    start = time.perf_counter()
    with open_executor(parse_executor(f"local:{workers}")) as pool:
        run_jobs(
            pool, timed_fleet_chunk, jobs, table, chunk=1, in_flight=2 * workers, failed=error_row
        )
    wall = time.perf_counter() - start
    table.close(sort=True)
    work = inside[0]
    print(
        f"  local:{workers} again, each job timed in its worker: {wall:.1f} s, work {work:.1f} s "
        f"({work / len(jobs):.2f} s a recording), overhead {100 * (workers * wall - work) / work:.1f} % "
        "of the work (the pool's start and the last job's tail included)"
    )
    return wall


def _listed(links: Path, bags: list[Path], count: int) -> list[Path]:
    """``count`` recordings cycling over ``bags``: a fleet names each recording once, so the
    distinct ones are listed over and over under names of their own (symbolic links), as a
    fleet of robots recording the same route would be."""
    links.mkdir(parents=True, exist_ok=True)
    fleet = []
    for i in range(count):
        link = links / f"robot{i:04d}"
        if not link.is_symlink():
            link.symlink_to(bags[i % len(bags)].resolve())
        fleet.append(link)
    return fleet


def throughput(
    folder: Path, recordings: int, minutes: float, distinct: int, workers: int, repeats: int
) -> None:
    bags = simulated(folder, minutes, range(1, distinct + 1))
    fleet = _listed(folder / "fleet", bags, recordings)
    print(f"fleet calibrate: {recordings} recordings of {minutes:g} min ({distinct} distinct)")
    serials, locals_ = [], []
    for _ in range(repeats):  # interleaved; the least disturbed (shortest) of each is kept
        serials.append(_fleet(fleet, "calibrate", "serial", folder / "serial"))
        locals_.append(_fleet(fleet, "calibrate", f"local:{workers}", folder / "local"))
    serial, local = min(serials), min(locals_)
    same = (folder / "serial" / "fleet.csv").read_text() == (
        folder / "local" / "fleet.csv"
    ).read_text()
    print(f"  serial (baseline)  {serial:8.1f} s  {recordings / serial:6.2f} recordings/s")
    print(f"  local:{workers}            {local:8.1f} s  {recordings / local:6.2f} recordings/s")
    print(f"  speed-up serial/local:{workers}: {serial / local:.2f}x  (tables identical: {same})")
    print(f"  load average after: {os.getloadavg()[0]:.1f}")
    again = pool_overhead(fleet, workers, folder / "timed")
    print(f"  speed-up serial/local:{workers} (timed run): {serial / again:.2f}x")


def _memory_child(bag: str, count: int, workers: int, out: str) -> None:
    import omnical.reports.fleet as report

    write = report.write_fleet_report
    before: list[float] = []

    def measured(*args: Any, **kwargs: Any) -> Path:
        before.append(_vmhwm_mb())  # the runs' peak, before the report's table and figure
        return write(*args, **kwargs)

    report.write_fleet_report = measured  # type: ignore[assignment]
    bags = _listed(Path(out).with_name(Path(out).name + "-links"), [Path(bag)], count)
    _fleet(bags, "locate", f"local:{workers}", Path(out))
    print(json.dumps({"vmhwm_mb": _vmhwm_mb(), "runs_mb": before[0]}))


def memory(folder: Path, counts: list[int], workers: int) -> None:
    (bag,) = simulated(folder, 1.0, range(1, 2))
    print("coordinator peak memory, fleet locate of a 1-minute recording on local:2:")
    base = None
    for count in counts:
        args = [sys.executable, __file__, "--child", str(bag), str(count), str(workers)]
        start = time.perf_counter()
        done = subprocess.run(
            [*args, str(folder / f"mem{count}")], check=True, capture_output=True, text=True
        )
        wall = time.perf_counter() - start
        figures = json.loads(done.stdout.strip().splitlines()[-1])
        peak, runs = figures["vmhwm_mb"], figures["runs_mb"]
        base = base or peak
        print(
            f"  {count:6d} recordings  {peak:7.1f} MB  ({peak / base:.2f}x)  {wall:6.1f} s"
            f"  (before the report: {runs:.1f} MB)"
        )


def main(argv: list[str]) -> None:
    if argv[:1] == ["--child"]:
        _memory_child(argv[1], int(argv[2]), int(argv[3]), argv[4])
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recordings", type=int, default=100)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--distinct", type=int, default=4)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--counts", type=int, nargs="*", default=[10, 100, 1000])
    parser.add_argument("--folder", type=Path, help="keep the recordings here (reused)")
    parser.add_argument("--no-throughput", action="store_true")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.folder or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        if not args.no_throughput:
            throughput(
                folder, args.recordings, args.minutes, args.distinct, args.workers, args.repeats
            )
        if args.counts:
            memory(folder, args.counts, args.workers)


if __name__ == "__main__":
    main(sys.argv[1:])

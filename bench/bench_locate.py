"""Benchmark: ``omnical locate`` on a 60-minute synthetic bag, compiled vs numpy Gauss–Newton.

The bag is ``bench_bag.py --scale``'s 60-minute one restricted to locate's topics: random
ranges from 100 hedgehog addresses (so 100 streams of ~1,150 sliding-window fixes, half of them
degenerate), the case issue "Scale" asks to run in ≤ 3 s. Measured in this run:

* in this process, on the decoded recording: :func:`omnical.ips.from_recording.locate` with
  ``SolverOptions(engine="numpy")`` and ``engine="compiled"`` (best of ``--repeats``; the
  compiled engine's first call, which loads the cached kernel and initialises numba, apart),
  the ratio, and ``write_fixes_csv``;
* in fresh processes, the whole of what ``omnical locate`` does (imports, ``read_bag``, locate,
  CSV) with each engine: wall and CPU time, numba's import and first-call cost included;
* the peak memory of that fresh process (``VmHWM`` of ``/proc/self/status``, engine numpy so
  that numba's ~115 MB do not hide it) for 1-, 10- and 60-minute bags (issue "Scale" item 3:
  flat in the recording length), beside a process that only imports.

Both engines give the same fixes bit for bit (checked here too).

Measured (2026-11-24, shared 2-core machine, the other core busy; before → after the
"Scale" work: the recording handed over and freed once the fixes are grouped, learning passes
holding only what the learning reads, the CSV formatted a chunk at a time):

* fresh-process peak (numpy engine): 1 min 61 → 53 MB, 10 min 81 → 69 MB, 60 min 115 → 98 MB;
  imports only 53 → 44 MB (pydantic is imported when a map file is read, not with
  ``omnical.ips``). Still not flat: the fixes of a pass (~0.1 kB a fix) and the learning's
  temporaries (bounded at 40,000 fixes) grow with the run;
* ``write_fixes_csv`` 0.7× its time;
* through the CLI on the lead's bags (best of 3, old and new alternated, load 1.5–2.5; CPU
  user, wall, peak; these include a numba start-up shortcut since dropped, ~0.15 s of CPU):
  60-minute random-range bag ``zstd60`` 3.27 → 3.10 s, 3.51 → 3.26 s,
  219 → 201 MB; 60-minute twin tour 1.96 → 1.90 s, 136 → 114 MB; 10 minutes 0.92 → 0.84 s,
  87 → 83 MB; 1 minute 0.57 → 0.51 s, 68 → 67 MB. The fixes CSV is byte-identical before
  and after on all of them and on the real CUHK-SZ and TU Chemnitz runs.

Run: ``PYTHONPATH=src .venv/bin/python bench/bench_locate.py [--minutes 60] [--repeats 3]
[--memory-only]``
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench_bag import LOCATE_TOPICS, mixed_recording
from omnical.ips.from_recording import locate, write_fixes_csv
from omnical.ips.solve import SolverOptions
from omnical.recording import Recording, read_bag, write_bag


def _child(path: str, engine: str, out: str) -> None:
    """What ``omnical locate`` does, with one engine (run in a fresh process)."""
    start = time.perf_counter()
    # handed over, not kept, as `omnical locate` does: its columns go once the fixes are grouped
    fixes, _ = locate(
        read_bag(Path(path), LOCATE_TOPICS),
        options=SolverOptions(engine=engine),  # type: ignore[arg-type]
    )
    write_fixes_csv(fixes, Path(out))
    print(f"{time.perf_counter() - start:.3f}")


def _child_memory(path: str, out: str) -> None:
    """:func:`_child` with the numpy engine, then the process's peak resident memory (kB);
    ``path`` "-" only imports."""
    if path != "-":
        _child(path, "numpy", out)
    status = Path("/proc/self/status").read_text(encoding="utf-8")
    print(next(line.split()[1] for line in status.splitlines() if line.startswith("VmHWM:")))


def _peak_kb(path: Path | str, out: Path) -> int:
    """VmHWM (kB) of a fresh process running :func:`_child_memory`."""
    done = subprocess.run(
        [sys.executable, __file__, "--child-memory", str(path), str(out)],
        check=True,
        capture_output=True,
        text=True,
    )
    return int(done.stdout.split()[-1])


def _peaks(root: Path, minutes: tuple[float, ...]) -> None:
    """Peak memory of ``omnical locate``'s work on bags of each length."""
    print("peak memory of a fresh process (VmHWM), read_bag + locate (numpy engine) + CSV:")
    print(f"  imports only: {_peak_kb('-', root / 'none.csv') / 1024:.0f} MB")
    for length in minutes:
        full = mixed_recording(np.random.default_rng(1), 60.0 * length)
        only = {t: full.topic(t) for t in LOCATE_TOPICS if full.has(t)}
        del full
        bag = write_bag(Recording(only), root / f"mem{length:g}")
        n = len(only["/beacon_raw_distance"])
        del only
        peak = _peak_kb(bag, root / f"mem{length:g}.csv")
        print(f"  {length:4g} min ({n:,} raw distances): {peak / 1024:.0f} MB")


def _fresh(path: Path, engine: str, out: Path) -> tuple[float, float]:
    """Wall and CPU seconds of a fresh process running :func:`_child`."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, __file__, "--child", str(path), engine, str(out)],
        check=True,
        capture_output=True,
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--memory-only", action="store_true", help="only the peak memory")
    args = parser.parse_args()
    if args.memory_only:
        with tempfile.TemporaryDirectory() as tmp:
            _peaks(Path(tmp), tuple(dict.fromkeys((1.0, 10.0, args.minutes))))
        return
    full = mixed_recording(np.random.default_rng(0), 60.0 * args.minutes)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        only = {t: full.topic(t) for t in LOCATE_TOPICS if full.has(t)}
        bag = write_bag(Recording(only), root / "bag")
        recording = read_bag(bag, LOCATE_TOPICS)
        n = len(recording.topic("/beacon_raw_distance"))
        print(f"{args.minutes:.0f}-minute synthetic bag: {n:,} raw distances")

        results = {}
        timings = {}
        for engine in ("numpy", "compiled"):
            options = SolverOptions(engine=engine)  # type: ignore[arg-type]
            runs = []
            for _ in range(args.repeats + (engine == "compiled")):
                start = time.perf_counter()
                results[engine], _ = locate(recording, options=options)
                runs.append(time.perf_counter() - start)
            if engine == "compiled":
                print(f"locate, compiled, first call (numba init + cached kernel): {runs[0]:.2f} s")
                runs = runs[1:]
            timings[engine] = min(runs)
            print(f"locate, {engine} engine: {timings[engine]:.2f} s (best of {args.repeats})")
        print(f"ratio numpy / compiled: {timings['numpy'] / timings['compiled']:.2f}×")
        same = all(
            np.array_equal(
                getattr(results["numpy"], name), getattr(results["compiled"], name), equal_nan=True
            )
            for name in ("positions_map_m", "covariance_xy_m2", "status", "reason")
        )
        print(f"fixes identical: {same} ({len(results['numpy']):,} fixes)")
        start = time.perf_counter()
        write_fixes_csv(results["numpy"], root / "fixes.csv")
        print(f"write_fixes_csv: {time.perf_counter() - start:.2f} s")

        print("fresh process, read_bag + locate + CSV (what `omnical locate` runs):")
        for engine in ("numpy", "compiled", "auto"):
            wall, cpu = _fresh(bag, engine, root / f"{engine}.csv")
            print(f"  engine {engine:8s}: wall {wall:.2f} s, CPU {cpu:.2f} s")
        _peaks(root, tuple(dict.fromkeys((1.0, 10.0, args.minutes))))


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--child":
        _child(*sys.argv[2:])
    elif len(sys.argv) == 4 and sys.argv[1] == "--child-memory":
        _child_memory(*sys.argv[2:])
    else:
        main()

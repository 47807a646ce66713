"""Benchmark: ``omnical locate`` of this checkout against a baseline commit's, in one run.

The 100-hedgehog stress bag (``bench_bag``), CUHK-SZ, TU Chemnitz and a 60-minute twin tour, in
fresh processes, baseline and new alternated: wall, CPU, peak, the ratio, the CSVs compared.
Run: ``.venv/bin/python bench/bench_locate.py [--repeats 5] [--baseline cf7fb94]``"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench_bag import LOCATE_TOPICS, mixed_recording
from omnical.bags.bag import write_bag
from omnical.recording.recording import Recording

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "cf7fb94"
"""The last commit with the second locate path (``ips/windowed.py``) and its process tricks."""
_LOOP = (
    "  - hold: {duration_s: 3.0}\n  - move: {vx_mps: 0.25, distance_m: 2.5}\n"
    "  - hold: {duration_s: 2.0}\n  - move: {vy_mps: 0.2, distance_m: 2.0}\n"
    "  - hold: {duration_s: 2.0}\n  - move: {wz_radps: 0.8, angle_deg: 1080}\n"
    "  - hold: {duration_s: 2.0}\n  - move: {vx_mps: -0.25, distance_m: 2.5}\n"
    "  - hold: {duration_s: 2.0}\n  - move: {vy_mps: -0.2, distance_m: 2.0}\n"
    "  - hold: {duration_s: 3.0}\n"
)
"""The tour's 80-s loop (as ``bench_evaluate.py``'s): 45 of them are the 60-minute tour."""


def _bags(root: Path) -> dict[str, Path]:
    spec = importlib.util.spec_from_file_location("uwb_bags", ROOT / "tests/ips/uwb_bags.py")
    assert spec is not None and spec.loader is not None
    uwb = importlib.util.module_from_spec(spec)
    sys.modules["uwb_bags"] = uwb  # its dataclasses look their module up
    spec.loader.exec_module(uwb)
    full = mixed_recording(np.random.default_rng(0), 3600.0)
    only = Recording({t: full.topic(t) for t in LOCATE_TOPICS if full.has(t)})
    del full
    script = root / "tour60.yaml"
    script.write_text("name: tour60\nsteps:\n" + _LOOP * 45, encoding="utf-8")
    subprocess.run(
        [sys.executable, "-m", "omnical.cli.main", "simulate", str(script), "--out",
         str(root / "tour60.mcap")],
        check=True, capture_output=True,
    )  # fmt: skip
    return {
        "stress (100 hedgehogs)": write_bag(only, root / "stress"),
        "CUHK-SZ": write_bag(uwb.cuhksz_run().recording, root / "cuhksz"),
        "TU Chemnitz": write_bag(uwb.tuc_run().recording, root / "tuc"),
        "60-min twin tour": root / "tour60",
    }


def _run(src: Path, bag: Path, out: Path) -> tuple[float, float, float]:
    """``omnical locate BAG --out OUT`` of the sources ``src`` in a fresh process: wall and
    CPU seconds, peak MB (``/usr/bin/time``'s: the process's own, not the bench's). Exit
    status 3 (fixes written, but poor or not plausible: the stress bag's random ranges) is
    accepted."""
    stats = out.with_suffix(".time")
    done = subprocess.run(
        ["/usr/bin/time", "-o", str(stats), "-f", "%e %U %S %M", sys.executable, "-c",
         "from omnical.cli.main import main; main()", "locate", str(bag), "--out", str(out),
         "--overwrite"],
        check=False, capture_output=True, env={**os.environ, "PYTHONPATH": str(src)},
    )  # fmt: skip
    if done.returncode not in (0, 3):
        done.check_returncode()
    wall, user, system, peak_kb = stats.read_text(encoding="utf-8").split()[-4:]
    return float(wall), float(user) + float(system), int(peak_kb) / 1024


def _compare(old: Path, new: Path) -> str:
    """How the two fixes CSVs differ: rows, the columns, the fewest significant digits that
    agree in a number that differs; text columns (beacons, status, reason) exactly."""
    a = old.read_text(encoding="utf-8").splitlines()
    b = new.read_text(encoding="utf-8").splitlines()
    if a == b:
        return "CSV identical"
    if len(a) != len(b) or a[0] != b[0]:
        return f"CSV differs: {len(a) - 1} vs {len(b) - 1} rows"
    header = a[0].split(",")
    rows, columns, digits, text = 0, set(), np.inf, 0
    for x, y in zip(a[1:], b[1:], strict=True):
        if x == y:
            continue
        rows += 1
        for name, u, v in zip(header, x.split(","), y.split(","), strict=True):
            if u == v:
                continue
            columns.add(name)
            if name in {"beacons_used", "status", "reason"}:
                text += 1
                continue
            fu, fv = float(u), float(v)
            digits = min(digits, -np.log10(abs(fu - fv) / max(abs(fu), abs(fv))))
    return (
        f"{rows} of {len(a) - 1} rows differ ({', '.join(sorted(columns))}; text cells "
        f"{text}; numbers agree to {digits:.1f} significant digits at least)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--baseline", default=BASELINE, help="commit to compare with")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        old = root / "baseline"
        old.mkdir()
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", args.baseline, "src"],
            check=False, capture_output=True,
        )  # fmt: skip
        if archive.returncode != 0:
            print(
                f"bench_locate: no baseline {args.baseline} in {ROOT}: give --baseline",
                file=sys.stderr,
            )
            sys.exit(2)
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive.stdout, check=True)
        sources = {"baseline": old / "src", "new": ROOT / "src"}
        bags = _bags(root)
        print(f"omnical locate, baseline {args.baseline} vs this checkout, fresh processes,")
        print(f"alternated, {args.repeats} runs each (median wall; CPU = user + sys; peak RSS):")
        for name, bag in bags.items():
            for which, src in sources.items():  # numba's cache filled, files warm
                _run(src, bag, root / f"{which}.csv")
            runs: dict[str, list[tuple[float, float, float]]] = {w: [] for w in sources}
            for _ in range(args.repeats):
                for which, src in sources.items():
                    runs[which].append(_run(src, bag, root / f"{which}.csv"))
            wall = {w: statistics.median(r[0] for r in runs[w]) for w in runs}
            for which, timed in runs.items():
                cpu = statistics.median(r[1] for r in timed)
                peak = max(r[2] for r in timed)
                low, high = min(r[0] for r in timed), max(r[0] for r in timed)
                print(
                    f"  {name:24s} {which:8s} wall {wall[which]:5.2f} s ({low:.2f}–{high:.2f}), "
                    f"CPU {cpu:5.2f} s, peak {peak:4.0f} MB"
                )
            print(
                f"  {name:24s} ratio new / baseline (wall): {wall['new'] / wall['baseline']:.2f}×"
            )
            print(f"  {name:24s} {_compare(root / 'baseline.csv', root / 'new.csv')}")
        load = Path("/proc/loadavg").read_text(encoding="utf-8").split()[:3]
        print(f"load average at the end: {' '.join(load)}")


if __name__ == "__main__":
    main()

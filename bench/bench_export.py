"""Export benchmark (issue "Scale"): ``omnical export`` of 1, 10 and 60-minute bags to CSV.

Two ways of writing the same files, each measured in a fresh process (time, CPU time and peak
memory, VmHWM from /proc/self/status), on the same bag:

* ``stream``: :func:`export_bag_csv`, what ``omnical export`` does: topics read part by part
  from the MCAP chunks (:class:`omnical.bags.bag.BagStream`) and appended to their files;
* ``old``: the export before the change: ``read_bag`` then rows as Python objects through
  :func:`csv.writer`, 20,000 at a time (a copy of the writer it used, below).

The ratios say how many times longer / more memory ``old`` takes than ``stream``. The files of
the two are compared byte for byte. Bags are synthetic, the twin's topic rates with random
values (``bench_bag.mixed_recording``; every float has 16-17 significant digits, the costliest to
format), zstd chunks as ``omnical simulate`` writes them. Other bags can be given instead.

Run: ``.venv/bin/python bench/bench_export.py`` or ``... bench/bench_export.py BAG [BAG ...]``.
Timings on a shared machine are noisy: CPU time is the steadier figure.
"""

from __future__ import annotations

import csv
import filecmp
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

KINDS = ("stream", "old")


def _old_export_csv(recording: Any, out: Path) -> None:
    """The CSV export as it was: whole tables, rows as Python objects through csv.writer."""
    out.mkdir(parents=True, exist_ok=True)
    for topic, table in recording.tables.items():
        header = ["t_ns"]
        columns = [table.t_ns]
        for name in table.names:
            values = table[name]
            if values.ndim == 1:
                header.append(name)
                columns.append(values)
            else:
                header.extend(f"{name}.{i}" for i in range(values.shape[1]))
                columns.extend(values[:, i] for i in range(values.shape[1]))
        stem = topic.strip("/").replace("/", "_") or "root"
        with (out / f"{stem}.csv").open("w", newline="", encoding="utf-8") as stream:
            writer = csv.writer(stream)
            writer.writerow(header)
            for start in range(0, len(table), 20_000):
                part = slice(start, start + 20_000)
                writer.writerows(zip(*(c[part].tolist() for c in columns), strict=True))


def _child(kind: str, bag: str, out: str) -> None:
    """One export in this fresh process; prints wall s, CPU s and peak RSS (MB)."""
    from omnical.bags.bag import read_bag
    from omnical.bags.export import export_bag_csv

    start, cpu = time.perf_counter(), time.process_time()
    if kind == "stream":
        export_bag_csv(bag, out)
    else:
        _old_export_csv(read_bag(bag), Path(out))
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    # VmHWM, not ru_maxrss: the latter keeps the parent's peak across fork + exec.
    status = Path("/proc/self/status").read_text().splitlines()
    peak_kb = next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
    print(f"{seconds} {cpu} {peak_kb / 1024}")


def measure(kind: str, bag: Path, out: Path) -> tuple[float, float, float]:
    """Wall seconds, CPU seconds and peak MB of one export ``kind`` in a fresh process."""
    shutil.rmtree(out, ignore_errors=True)
    result = subprocess.run(
        [sys.executable, __file__, "--child", kind, str(bag), str(out)],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return float(result[0]), float(result[1]), float(result[2])


def _same_files(a: Path, b: Path) -> bool:
    names = sorted(p.name for p in a.iterdir())
    if names != sorted(p.name for p in b.iterdir()):
        return False
    _, mismatch, errors = filecmp.cmpfiles(a, b, names, shallow=False)
    return not mismatch and not errors


def compare(label: str, bag: Path, work: Path) -> None:
    """Measure the two exports of ``bag`` and print one line each, with the ratio."""
    from omnical.bags.bag import indexed_mcap

    summary = indexed_mcap(bag) if bag.is_dir() or bag.suffix == ".mcap" else None
    count = f"{summary.message_count:,} messages" if summary is not None else str(bag)
    print(f"--- {label}: {count}")
    figures = {kind: measure(kind, bag, work / kind) for kind in KINDS}
    stream = figures["stream"]
    for kind, (seconds, cpu, mb) in figures.items():
        ratio = (
            ""
            if kind == "stream"
            else f"   {kind}/stream: {seconds / stream[0]:.2f}x time, {cpu / stream[1]:.2f}x CPU, "
            f"{mb / stream[2]:.2f}x memory"
        )
        print(f"{kind:<7} {seconds:7.2f} s  CPU {cpu:7.2f} s  peak {mb:7.1f} MB{ratio}")
    same = _same_files(work / "stream", work / "old")
    print(f"files identical byte for byte: {'yes' if same else 'NO'}")


def main(bags: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if bags:
            for bag in bags:
                compare(bag, Path(bag), work)
            return
        from bench_bag import mixed_recording
        from omnical.bags.bag import write_bag

        for minutes in (1, 10, 60):
            recording = mixed_recording(np.random.default_rng(minutes), 60.0 * minutes)
            bag = write_bag(recording, work / f"run{minutes}")
            del recording
            compare(f"{minutes} min", bag, work)
            shutil.rmtree(bag)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        _child(sys.argv[2], sys.argv[3], sys.argv[4])
    else:
        main(sys.argv[1:])

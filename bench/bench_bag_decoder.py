"""Benchmark: reading bags with this checkout's decoder against a baseline commit's, in one run.

CUHK-SZ, TU Chemnitz, a 60-minute twin tour (MCAP, ROS 1) in fresh processes, old and new taking
turns: read_bag whole, of chosen topics, and part by part (read_selected); CPU s, ratio, digests.
Run: ``.venv/bin/python bench/bench_bag_decoder.py [--repeats 3] [--baseline aa7ccd0]``"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_bag import LOCATE_TOPICS
from bench_mcap_library import write_tour
from omnical.bags.bag import read_bag, write_bag

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "aa7ccd0"
"""The last commit with two decoders (``StreamDecoder`` for ``read_bag`` beside ``BagStream``)."""

_CHILD = """
import hashlib, sys, time
from omnical.bags.bag import read_bag
from omnical.bags.stream import read_selected
kind, path, topics = sys.argv[1], sys.argv[2], sys.argv[3].split(",") if sys.argv[3] else None
start, wall = time.process_time(), time.perf_counter()
if kind == "stream":
    rec = read_selected(path, topics, {})
else:
    rec = read_bag(path, topics)
cpu, wall = time.process_time() - start, time.perf_counter() - wall
digest = hashlib.sha256()
for name in rec.topics:
    table = rec.topic(name)
    digest.update(name.encode() + table.t_ns.tobytes())
    for column in table.names:
        values = table[column]
        data = repr(values.tolist()).encode() if values.dtype.kind == "O" else values.tobytes()
        digest.update(column.encode() + str(values.dtype).encode() + data)
digest.update(repr(rec.notes).encode())
if kind != "stream":
    digest.update(repr(sorted(rec.skipped_topics.items())).encode())
print(cpu, wall, sum(len(rec.topic(n)) for n in rec.topics), digest.hexdigest()[:12])
"""


def _bags(root: Path) -> dict[str, Path]:
    spec = importlib.util.spec_from_file_location("uwb_bags", ROOT / "tests/ips/uwb_bags.py")
    assert spec is not None and spec.loader is not None
    uwb = importlib.util.module_from_spec(spec)
    sys.modules["uwb_bags"] = uwb  # its dataclasses look their module up
    spec.loader.exec_module(uwb)
    script = root / "tour60.yaml"
    write_tour(script, 60.0)
    subprocess.run(
        [sys.executable, "-m", "omnical.cli.main", "simulate", str(script), "--out",
         str(root / "tour60.mcap")],
        check=True, capture_output=True,
    )  # fmt: skip
    cuhksz, tuc = uwb.cuhksz_run().recording, uwb.tuc_run().recording
    return {
        "CUHK-SZ mcap": write_bag(cuhksz, root / "cuhksz"),
        "CUHK-SZ ros1": write_bag(cuhksz, root / "cuhksz.bag"),
        "TU Chemnitz mcap": write_bag(tuc, root / "tuc"),
        "TU Chemnitz ros1": write_bag(tuc, root / "tuc.bag"),
        "60-min tour mcap": root / "tour60",
        "60-min tour ros1": write_bag(read_bag(root / "tour60"), root / "tour60.bag"),
    }


def _run(src: Path, kind: str, bag: Path, topics: str) -> tuple[float, float, int, str]:
    """One read in a fresh process: CPU s, wall s, rows, digest of the tables and notes."""
    done = subprocess.run(
        [sys.executable, "-c", _CHILD, kind, str(bag), topics],
        check=True, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(src)},
    )  # fmt: skip
    cpu, wall, rows, digest = done.stdout.split()
    return float(cpu), float(wall), int(rows), digest


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
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
                f"bench_bag_decoder: no baseline {args.baseline}: give --baseline", file=sys.stderr
            )
            sys.exit(2)
        subprocess.run(["tar", "-x", "-C", str(old)], input=archive.stdout, check=True)
        sources = {"baseline": old / "src", "new": ROOT / "src"}
        print(
            f"{'bag':<17} {'read':<14} {'rows':>9} {'baseline':>9} {'new':>9} {'ratio':>6}  output"
        )
        for name, bag in _bags(root).items():
            chosen = "/odom" if "tour" in name else ",".join(LOCATE_TOPICS)
            for kind, topics in [("read_bag", ""), ("read_bag", chosen), ("stream", "")]:
                label = f"{kind} {'selected' if topics else 'all'}"
                cpu: dict[str, list[float]] = {"baseline": [], "new": []}
                seen: dict[str, set[tuple[int, str]]] = {"baseline": set(), "new": set()}
                for _ in range(args.repeats):
                    for which, src in sources.items():
                        c, _wall, rows, digest = _run(src, kind, bag, topics)
                        cpu[which].append(c)
                        seen[which].add((rows, digest))
                a, b = statistics.median(cpu["baseline"]), statistics.median(cpu["new"])
                same = "identical" if seen["baseline"] == seen["new"] else "DIFFERS"
                rows = next(iter(seen["new"]))[0]
                print(
                    f"{name:<17} {label:<14} {rows:>9} {a:>8.3f}s {b:>8.3f}s {b / a:>6.2f}  {same}",
                    flush=True,
                )


if __name__ == "__main__":
    main()

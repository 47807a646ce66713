"""`make bench` runs every benchmark the README quotes (issue 24)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _bench_target(makefile: str) -> str:
    """The recipe lines of the Makefile's ``bench`` target."""
    lines = makefile.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("bench:"))
    recipe = []
    for line in lines[start + 1 :]:
        if not line.startswith("\t"):
            break
        recipe.append(line)
    return "\n".join(recipe)


def test_make_bench_runs_every_benchmark_the_readme_quotes() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    quoted = set(re.findall(r"bench/(bench_\w+\.py)", readme))
    assert len(quoted) >= 10  # the README quotes its benchmarks by path
    recipe = _bench_target((ROOT / "Makefile").read_text(encoding="utf-8"))
    missing = sorted(s for s in quoted if f"bench/{s}" not in recipe)
    assert not missing, f"quoted in README.md but not run by `make bench`: {missing}"
    assert all((ROOT / "bench" / s).is_file() for s in quoted)

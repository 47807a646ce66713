"""Start-up benchmark: how long ``omnical`` takes before it does any work.

Times, as the best of several subprocess runs each (after one untimed warm-up run):

* ``python -c pass``: the interpreter alone;
* a bare typer app with one command, ``--help``: the floor any typer CLI pays (the baseline);
* ``omnical --help`` (target ≤ 300 ms on a quiet machine);
* ``omnical <command> --help`` for every command;
* one cheap real invocation per command on tiny inputs made in a temporary directory (a tiny
  bag, a 0.2 s motion script): the command's fixed start-up, i.e. its imports and set-up
  (target ≤ 500 ms). Some of them stop at a user error (exit 2) once the command's body is
  imported, which is the part measured; the exit status is printed beside each figure.

Each figure is printed in ms with its ratio to the bare-typer baseline, and the load average
before and after (the figures mean little on a busy machine). The runs cache bytecode in a
temporary ``PYTHONPYCACHEPREFIX``, as an installed package has it, even when the environment
sets ``PYTHONDONTWRITEBYTECODE`` (an editable checkout without ``__pycache__`` would otherwise
recompile omnical's sources at every start).

Run: ``.venv/bin/python bench/bench_startup.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

HELP_TARGET_MS = 300.0
COMMAND_TARGET_MS = 500.0

BARE_TYPER = '''\
import typer

app = typer.Typer()


@app.command()
def hello(name: str = "world") -> None:
    """Say hello."""
    print(f"hello {name}")


app()
'''

TINY_SCRIPT = "name: tiny\nsteps:\n  - hold: {duration_s: 0.2}\n"


@dataclass(frozen=True)
class Case:
    """One command line to time."""

    label: str
    argv: list[str]
    target_ms: float | None = None


@dataclass(frozen=True)
class Timing:
    """Wall times of the runs of one case, s, and the exit status of the last run."""

    runs_s: list[float]
    returncode: int

    @property
    def best_ms(self) -> float:
        """Fastest run, ms (the least disturbed by other processes)."""
        return 1e3 * min(self.runs_s)

    @property
    def median_ms(self) -> float:
        """Median run, ms."""
        return 1e3 * statistics.median(self.runs_s)


def time_case(case: Case, repeats: int, cwd: Path, env: dict[str, str]) -> Timing:
    """Run ``case`` once untimed (it also fills the bytecode cache), then ``repeats`` times."""
    runs: list[float] = []
    returncode = 0
    for i in range(repeats + 1):
        t0 = time.perf_counter()
        proc = subprocess.run(
            case.argv,
            cwd=cwd,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            check=False,
        )
        elapsed = time.perf_counter() - t0
        returncode = proc.returncode
        if i > 0:
            runs.append(elapsed)
    return Timing(runs, returncode)


def omnical_command() -> list[str]:
    """The installed console script next to this interpreter, else ``python -m``."""
    script = shutil.which("omnical", path=str(Path(sys.executable).parent))
    return [script] if script else [sys.executable, "-m", "omnical.cli.main"]


def make_inputs(directory: Path) -> tuple[Path, Path]:
    """A tiny bag (0.1 s of /cmd_vel and /odom) and a 0.2 s motion script."""
    from omnical.bags.bag import write_bag
    from omnical.recording.recording import RecordingBuilder

    builder = RecordingBuilder()
    for k in range(6):
        t_ns = 1_000_000_000 + k * 20_000_000
        builder.add("/cmd_vel", t_ns, vx_mps=0.1, vy_mps=0.0, wz_radps=0.0)
    bag = write_bag(builder.build(), directory / "tiny.mcap")
    script = directory / "tiny.yaml"
    script.write_text(TINY_SCRIPT, encoding="utf-8")
    return bag, script


def cases(directory: Path, bag: Path, script: Path) -> list[Case]:
    """Every command line to time, baseline first."""
    bare = directory / "bare_typer.py"
    bare.write_text(BARE_TYPER, encoding="utf-8")
    omnical = omnical_command()
    out = directory / "out"
    helps = [
        ["simulate"],
        ["info"],
        ["export"],
        ["locate"],
        ["evaluate"],
        ["calibrate"],
        ["calibrate", "campaign"],
        ["calibrate", "estimate"],
        ["demo"],
        ["fleet", "calibrate"],
        ["sweep"],
    ]
    real = [
        (
            "simulate 0.2 s script",
            ["simulate", str(script), "--out", str(out / "sim.mcap"), "--overwrite"],
        ),
        ("info tiny bag", ["info", str(bag)]),
        ("export tiny bag", ["export", str(bag), "--out", str(out / "csv")]),
        ("locate tiny bag", ["locate", str(bag), "--out", str(out / "fixes.csv")]),
        ("evaluate tiny bag", ["evaluate", str(bag), "--out", str(out / "ev")]),
        ("calibrate estimate tiny bag", ["calibrate", "estimate", str(bag), "--out", "f.yaml"]),
        ("calibrate campaign (bad --out)", ["calibrate", "campaign", "--out", "d.yaml"]),
    ]
    return [
        Case("python -c pass", [sys.executable, "-c", "pass"]),
        Case("bare typer app --help (baseline)", [sys.executable, str(bare), "--help"]),
        Case("omnical --help", [*omnical, "--help"], HELP_TARGET_MS),
        *(Case(f"omnical {' '.join(h)} --help", [*omnical, *h, "--help"]) for h in helps),
        *(Case(f"omnical {label}", [*omnical, *argv], COMMAND_TARGET_MS) for label, argv in real),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per case (best of)")
    args = parser.parse_args()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="omnical-startup-") as tmp:
        directory = Path(tmp)
        bag, script = make_inputs(directory)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = str(directory / "pycache")
        timings = [
            (case, time_case(case, max(args.repeats, 1), directory, env))
            for case in cases(directory, bag, script)
        ]
    load_after = os.getloadavg()
    baseline_ms = timings[1][1].best_ms
    print(f"start-up, best of {args.repeats} runs (ms); ratio to the bare typer app")
    print(f"load average before {load_before[0]:.2f}, after {load_after[0]:.2f} (1 min)")
    width = max(len(case.label) for case, _ in timings)
    print(f"{'':{width}}  {'best':>7}  {'median':>7}  {'ratio':>6}  exit  target")
    for case, timing in timings:
        verdict = ""
        if case.target_ms is not None:
            ok = timing.best_ms <= case.target_ms
            verdict = f"{'ok' if ok else 'OVER'} (≤ {case.target_ms:.0f})"
        print(
            f"{case.label:{width}}  {timing.best_ms:7.0f}  {timing.median_ms:7.0f}  "
            f"{timing.best_ms / baseline_ms:5.2f}x  {timing.returncode:>4}  {verdict}"
        )


if __name__ == "__main__":
    main()

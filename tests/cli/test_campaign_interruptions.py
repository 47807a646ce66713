"""SIGINT / SIGTERM at several moments of ``calibrate campaign --overwrite`` (real processes, real
signals): the earlier campaign stays byte-identical, the new one is kept as ``OUT.partial``."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from omnical.bags.bag import read_bag
from omnical.cli.main import app
from omnical.reports.outputs import MARKER

_CAMPAIGN = ["calibrate", "campaign", "--max-iterations", "1", "--no-validate", "--no-figures"]

_PAUSING_OMNICAL = """
import sys, time
from pathlib import Path
flag, point = Path(sys.argv.pop(1)), sys.argv.pop(1)

def pause(seconds):  # the test signals once the flag is there
    flag.touch()
    time.sleep(seconds)

if point == "run":  # the third progress event of the campaign: the robot is running
    import omnical.calibration.campaign as campaign
    run_campaign = campaign.run_campaign
    def run_paused(*args, on_progress=None, **kwargs):
        events = []
        def progress(event):
            events.append(event)
            if len(events) == 3:
                pause(30)
            if on_progress is not None:
                on_progress(event)
        return run_campaign(*args, on_progress=progress, **kwargs)
    campaign.run_campaign = run_paused
elif point == "write":  # the final write: factors and two recordings written, one to come
    import omnical.reports.campaign as campaign
    write_bag = campaign.write_bag
    def writing(*args, **kwargs):
        written = write_bag(*args, **kwargs)
        if len(list(written.parent.iterdir())) == 2:
            pause(30)
        return written
    campaign.write_bag = writing
elif point == "swap":  # the output complete, at its last check before the swap (signals held)
    import omnical.bags.staging as staging
    import omnical.reports.outputs as outputs
    check = outputs._check_directory
    def checking(path, *, overwrite):
        if staging._HELD:  # the stop signals are held: the test's is noted, not raised
            pause(1.0)
        return check(path, overwrite=overwrite)
    outputs._check_directory = checking
from omnical.cli.main import main
main()
"""


def _tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in root.rglob("*") if p.is_file()}


@pytest.fixture(scope="module")
def earlier(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A complete campaign, written in process: the output the interrupted ones must not touch."""
    out = tmp_path_factory.mktemp("campaign") / "cal"
    result = CliRunner().invoke(app, [*_CAMPAIGN, "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out


# Each moment with one signal: SIGINT and SIGTERM reach the same handler (cli/errors.py's
# _on_stop; Terminated is a KeyboardInterrupt), which differ only in the exit status and the
# word, checked at "run" (143) and at "write" and "swap" (130).
@pytest.mark.parametrize(
    ("point", "sig", "kept"),
    [
        ("run", signal.SIGTERM, ()),  # nothing written yet: nothing to keep
        ("write", signal.SIGINT, ("factors.yaml", "recordings/iter1-rotation/metadata.yaml")),
        ("swap", signal.SIGINT, ("report.md", "recordings/iter1-lateral/metadata.yaml")),
    ],
)
def test_a_stop_keeps_the_earlier_campaign_and_the_new_one_as_partial(
    earlier: Path, tmp_path: Path, point: str, sig: signal.Signals, kept: tuple[str, ...]
) -> None:
    import shutil

    out = tmp_path / "cal"
    shutil.copytree(earlier, out)
    before = _tree(out)
    flag = tmp_path / "paused"
    proc = subprocess.Popen(
        [sys.executable, "-c", _PAUSING_OMNICAL, str(flag), point, *_CAMPAIGN, "--out", str(out), "--overwrite"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 180  # to the pause point (load 20: > 60 s)
        while not flag.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert flag.exists(), proc.communicate()[1]
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    word = "interrupted" if sig == signal.SIGINT else "terminated"
    assert proc.returncode == (130 if sig == signal.SIGINT else 143), err
    assert err.strip().splitlines()[-1] == f"omnical: {word}"
    assert "Traceback" not in err
    assert _tree(out) == before  # the earlier campaign, byte for byte
    partial = tmp_path / "cal.partial"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["cal", "paused", *(["cal.partial"] if kept else [])]
    )  # no staging directory left behind
    if kept:
        assert (
            f"omnical: kept the unfinished output in {partial}; the earlier {out} was not touched"
            in err
        )
        assert (partial / MARKER).read_text().startswith("written by omnical calibrate campaign")
        for name in kept:
            assert (partial / name).is_file(), name
        run = read_bag(partial / "recordings" / "iter1-rotation")
        assert run.has("/cmd_vel")
    if point == "write":
        assert not (partial / "report.md").exists()  # the write was cut before the report
        assert len(list((partial / "recordings").iterdir())) == 2

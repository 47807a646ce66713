"""Output paths are checked before the work and nothing that is not omnical's is replaced."""

from __future__ import annotations

from pathlib import Path

import pytest

from omnical.errors import OutputError
from omnical.reports.outputs import (
    MARKER,
    claim_directory,
    claim_files,
    clear_in_claimed,
    side_file,
)


def test_a_directory_is_claimed_once_and_replaced_only_with_overwrite(tmp_path: Path) -> None:
    out = claim_directory(tmp_path / "run", overwrite=False, writer="test")
    assert (out / MARKER).read_text(encoding="utf-8") == "written by test\n"
    (out / "report.md").write_text("old", encoding="utf-8")
    with pytest.raises(OutputError, match="earlier omnical output; add --overwrite"):
        claim_directory(out, overwrite=False, writer="test")
    assert claim_directory(out, overwrite=True, writer="test") == out
    assert claim_directory(tmp_path / "empty-later", overwrite=False, writer="t").is_dir()


def test_a_claim_left_by_a_command_that_stopped_early_is_as_good_as_empty(tmp_path: Path) -> None:
    out = claim_directory(tmp_path / "fresh", overwrite=False, writer="test")
    # the command then stopped on a typo in an input: nothing but the marker is there
    assert claim_directory(out, overwrite=False, writer="test") == out


def test_a_typo_does_not_block_the_corrected_command(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from omnical.cli.main import app
    from omnical.recording import RecordingBuilder, write_bag

    builder = RecordingBuilder()
    builder.add_many("/odom", [0, 10**9], x_m=[0.0, 0.1], y_m=[0.0, 0.0], yaw_rad=[0.0, 0.0],
                     vx_mps=[0.1, 0.1], vy_mps=[0.0, 0.0], wz_radps=[0.0, 0.0])  # fmt: skip
    bag = write_bag(builder.build(), tmp_path / "run.mcap")
    runner = CliRunner()
    out = tmp_path / "fresh"
    args = ["evaluate", str(bag), "--out", str(out), "--reference"]
    bad = runner.invoke(app, [*args, "circel"])  # a typo in an input, found after the claim
    assert bad.exit_code == 2 and "circel" in bad.output
    again = runner.invoke(app, [*args, "circel"])
    assert "--overwrite" not in again.output  # the same error as the first time, not a claim
    assert again.exit_code == 2


def test_someone_elses_directory_or_file_is_never_written(tmp_path: Path) -> None:
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "thesis.tex").write_text("precious", encoding="utf-8")
    for overwrite in (False, True):
        with pytest.raises(OutputError, match="not written by omnical"):
            claim_directory(theirs, overwrite=overwrite, writer="test")
    assert sorted(p.name for p in theirs.iterdir()) == ["thesis.tex"]
    a_file = tmp_path / "a-file"
    a_file.write_text("x", encoding="utf-8")
    with pytest.raises(OutputError, match="exists and is not a directory"):
        claim_directory(a_file, overwrite=True, writer="test")


def test_files_absent_or_omnicals_own_with_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "calib" / "rosy.yaml"
    assert side_file(out, ".h") == tmp_path / "calib" / "rosy.h"
    assert claim_files([out, side_file(out, ".h")], overwrite=False) == [out, out.with_suffix(".h")]
    out.write_text("# omnical calibrate estimate run.mcap\nscale: {}\n", encoding="utf-8")
    with pytest.raises(OutputError, match=r"rosy\.yaml: exists; add --overwrite"):
        claim_files([out], overwrite=False)
    assert claim_files([out], overwrite=True) == [out]
    foreign = side_file(out, ".h")
    foreign.write_text("/* my own firmware header */\n", encoding="utf-8")
    with pytest.raises(OutputError, match="not written by omnical; it is not replaced"):
        claim_files([out, foreign], overwrite=True)
    assert foreign.read_text(encoding="utf-8") == "/* my own firmware header */\n"
    with pytest.raises(OutputError, match="is a directory"):
        claim_files([tmp_path], overwrite=True)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs a read-only /proc")
def test_an_unwritable_place_is_refused_before_any_work() -> None:
    with pytest.raises(OutputError, match="cannot write"):
        claim_directory("/proc/self/omnical-out", overwrite=False, writer="test")
    with pytest.raises(OutputError, match="cannot write"):
        claim_files(["/proc/self/omnical-factors.yaml"], overwrite=False)


def test_inside_a_claimed_directory_earlier_outputs_are_replaced(tmp_path: Path) -> None:
    out = claim_directory(tmp_path / "run", overwrite=False, writer="test")
    old_bag = out / "recordings" / "lissajous"
    old_bag.mkdir(parents=True)
    (old_bag / "metadata.yaml").write_text("an older omnical's bag", encoding="utf-8")
    clear_in_claimed(out, "recordings", "figures")
    assert not (out / "recordings").exists()
    with pytest.raises(OutputError, match="was not claimed"):
        clear_in_claimed(tmp_path, "run")
    assert out.is_dir()


def test_every_figure_writer_leaves_a_figure_overwrite_recognises(tmp_path: Path) -> None:
    """``--overwrite`` replaces omnical's own figures only: each writer's PNG must be one."""
    import matplotlib.pyplot as plt

    from omnical.reports.figures import navigation
    from omnical.reports.figures._common import save_figure
    from omnical.reports.outputs import is_figure

    for name, finish in (("common", save_figure), ("navigation", navigation._finish)):
        fig, ax = plt.subplots()
        ax.plot([0, 1], [0, 1])
        assert is_figure(finish(fig, tmp_path / f"{name}.png")), name

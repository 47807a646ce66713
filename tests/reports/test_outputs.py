"""Output paths are checked before the work and nothing that is not omnical's is replaced."""

from __future__ import annotations

from pathlib import Path

import pytest

from omnical.errors import OutputError
from omnical.reports.outputs import (
    MARKER,
    claim_directory,
    claim_files,
    side_file,
    stage_files,
)


def _write(out: Path, writer: str = "omnical test", **files: str) -> None:
    """An omnical output at ``out`` (claimed, written whole), holding ``files``."""
    claimed = claim_directory(out, overwrite=True, writer=writer)
    with claimed.staged() as staging:
        for name, text in files.items():
            (staging / name).write_text(text, encoding="utf-8")


def test_a_directory_is_claimed_once_and_replaced_only_with_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "run"
    claimed = claim_directory(out, overwrite=False, writer="omnical test")
    assert not out.exists()  # a claim checks; nothing is made before the output is written
    with claimed.staged() as staging:
        assert staging.parent == tmp_path and staging.name.startswith(".run.omnical-out-")
        (staging / "report.md").write_text("old", encoding="utf-8")
    assert (out / MARKER).read_text(encoding="utf-8") == "written by omnical test\n"
    assert (out / "report.md").read_text(encoding="utf-8") == "old"
    with pytest.raises(OutputError, match="earlier omnical output; add --overwrite"):
        claim_directory(out, overwrite=False, writer="omnical test")
    with claim_directory(out, overwrite=True, writer="omnical test").staged() as staging:
        (staging / "report.md").write_text("new", encoding="utf-8")
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "report.md"]
    assert (out / "report.md").read_text(encoding="utf-8") == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging, no old copy


def test_a_marker_only_directory_is_as_good_as_empty(tmp_path: Path) -> None:
    out = tmp_path / "fresh"
    out.mkdir()
    (out / MARKER).write_text("written by omnical evaluate\n", encoding="utf-8")
    # left by an older omnical whose command stopped on a typo: nothing but the marker
    with claim_directory(out, overwrite=False, writer="omnical test").staged() as staging:
        (staging / "a").write_text("a", encoding="utf-8")
    assert (out / "a").is_file()


def test_an_exception_keeps_the_earlier_output_and_the_new_one_as_partial(
    tmp_path: Path,
) -> None:
    out = tmp_path / "run"
    _write(out, **{"report.md": "old"})
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    for error, partial in ((KeyboardInterrupt(), "run.partial"), (RuntimeError(), "run.partial-2")):
        claimed = claim_directory(out, overwrite=True, writer="omnical test")
        told: list[str] = []
        with pytest.raises(type(error)), claimed.staged(told.append) as staging:
            (staging / "report.md").write_text("new", encoding="utf-8")
            raise error
        assert {p.name: p.read_bytes() for p in out.iterdir()} == before
        assert (tmp_path / partial / "report.md").read_text(encoding="utf-8") == "new"
        assert claimed.kept_at == tmp_path / partial
        assert told == [
            f"kept the unfinished output in {tmp_path / partial}; the earlier {out} was not touched"
        ]


def test_an_error_before_anything_is_written_leaves_nothing(tmp_path: Path) -> None:
    out = tmp_path / "a" / "b" / "run"
    claimed = claim_directory(out, overwrite=False, writer="omnical test")
    with pytest.raises(OutputError, match="circel"), claimed.staged():
        raise OutputError("circel: no such reference")
    assert not any(tmp_path.iterdir())  # not even the parents it made


def test_a_full_disk_names_the_file_and_keeps_what_was_written(tmp_path: Path) -> None:
    import errno
    import os

    out = tmp_path / "run"
    claimed = claim_directory(out, overwrite=False, writer="omnical test")
    with pytest.raises(OutputError) as raised, claimed.staged() as staging:
        (staging / "metrics.json").write_text("{}", encoding="utf-8")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(staging / "figures" / "p.png"))
    assert str(raised.value) == (
        f"{out / 'figures' / 'p.png'}: cannot write: No space left on device; what was written "
        f"is kept in {tmp_path / 'run.partial'}, nothing was written at {out}"
    )
    claimed = claim_directory(out, overwrite=False, writer="omnical test")
    with pytest.raises(OutputError) as raised, claimed.staged():
        raise OSError(errno.EDQUOT, os.strerror(errno.EDQUOT))  # no file name: the output's
    assert str(raised.value) == f"{out}: cannot write: {os.strerror(errno.EDQUOT)}"


def test_a_stop_signal_at_the_swap_keeps_the_earlier_output(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A real SIGTERM sent at the last moment before the swap (signals are held there): the
    earlier output stays, the new one is kept as .partial, then the signal is handled by the
    handler in force (here one that raises KeyboardInterrupt, as the CLI's does)."""
    import os
    import signal

    import omnical.reports.outputs as outputs

    out = tmp_path / "run"
    _write(out, **{"report.md": "old"})
    claimed = claim_directory(out, overwrite=True, writer="omnical test")
    check = outputs._check_directory

    def signalled(path: Path, *, overwrite: bool) -> None:
        os.kill(os.getpid(), signal.SIGTERM)  # held: pending until the swap is decided
        check(path, overwrite=overwrite)

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(outputs, "_check_directory", signalled)
    previous = signal.signal(signal.SIGTERM, interrupt)
    told: list[str] = []
    try:
        with pytest.raises(KeyboardInterrupt), claimed.staged(told.append) as staging:
            (staging / "report.md").write_text("new", encoding="utf-8")
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert (out / "report.md").read_text(encoding="utf-8") == "old"
    assert (tmp_path / "run.partial" / "report.md").read_text(encoding="utf-8") == "new"
    kept = tmp_path / "run.partial"
    assert told == [f"kept the unfinished output in {kept}; the earlier {out} was not touched"]


def test_a_typo_does_not_block_the_corrected_command(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from omnical.bags.bag import write_bag
    from omnical.cli.main import app
    from omnical.recording.recording import RecordingBuilder

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
    (theirs / MARKER).write_text("my own omnical notes", encoding="utf-8")  # not omnical's marker
    for overwrite in (False, True):
        with pytest.raises(OutputError, match="not written by omnical"):
            claim_directory(theirs, overwrite=overwrite, writer="omnical test")
    assert sorted(p.name for p in theirs.iterdir()) == [MARKER, "thesis.tex"]
    a_file = tmp_path / "a-file"
    a_file.write_text("x", encoding="utf-8")
    with pytest.raises(OutputError, match="exists and is not a directory"):
        claim_directory(a_file, overwrite=True, writer="omnical test")
    link = tmp_path / "link"
    link.symlink_to(theirs)
    with pytest.raises(OutputError, match="is a symbolic link; omnical does not write through"):
        claim_directory(link, overwrite=True, writer="omnical test")


def test_files_are_omnicals_only_as_omnical_left_them(tmp_path: Path) -> None:
    out = tmp_path / "calib" / "rosy.yaml"
    assert side_file(out, ".h") == tmp_path / "calib" / "rosy.h"
    paths = [out, side_file(out, ".h")]
    assert claim_files(paths, overwrite=False) == [out, out.with_suffix(".h")]
    with stage_files(paths, overwrite=False).staged() as staged:
        for path in staged:
            path.write_text(f"{path.name}\n", encoding="utf-8")
    assert out.read_text(encoding="utf-8") == "rosy.yaml\n"
    with pytest.raises(OutputError, match=r"rosy\.yaml: exists; add --overwrite"):
        claim_files([out], overwrite=False)
    assert claim_files([out], overwrite=True) == [out]  # the manifest lists it as it is
    foreign = side_file(out, ".h")
    foreign.write_text("/* my own firmware header, made with omnical */\n", encoding="utf-8")
    with pytest.raises(OutputError, match="not written by omnical; it is not replaced"):
        claim_files([out, foreign], overwrite=True)
    assert (
        foreign.read_text(encoding="utf-8") == "/* my own firmware header, made with omnical */\n"
    )
    word = tmp_path / "calib" / "notes.yaml"
    word.write_text("# omnical calibrate estimate run.mcap\n", encoding="utf-8")  # a word only
    with pytest.raises(OutputError, match="not written by omnical"):
        claim_files([word], overwrite=True)
    with pytest.raises(OutputError, match="is a directory"):
        claim_files([tmp_path], overwrite=True)


def test_a_link_to_a_users_file_and_a_device_are_refused_unread(tmp_path: Path) -> None:
    mine = tmp_path / "mine.yaml"
    mine.write_text("omnical\n", encoding="utf-8")
    link = tmp_path / "factors.yaml"
    link.symlink_to(mine)
    with pytest.raises(OutputError, match=r"is a symbolic link to .*mine\.yaml; omnical does not"):
        claim_files([link], overwrite=True)
    assert mine.read_text(encoding="utf-8") == "omnical\n"
    for device in ("/dev/full", "/dev/zero"):
        if Path(device).exists():
            with pytest.raises(OutputError, match="is not a regular file"):
                claim_files([device], overwrite=True)


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs a read-only /proc")
def test_an_unwritable_place_is_refused_before_any_work() -> None:
    with pytest.raises(OutputError, match="cannot write"):
        claim_directory("/proc/self/omnical-out", overwrite=False, writer="omnical test")
    with pytest.raises(OutputError, match="cannot write"):
        claim_files(["/proc/self/omnical-factors.yaml"], overwrite=False)


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

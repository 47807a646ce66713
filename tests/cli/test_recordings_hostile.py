"""Recordings as untrusted input, and bag outputs that are never destroyed by surprise.

Crafted bags (huge, duplicated and backward times, NaN and out-of-range values, unknown topics,
truncations) through ``read_bag``, ``summarize_bag`` and ``omnical info``: every case ends in a
result or one ``RecordingError``. Outputs: ``--overwrite`` replaces only a bag omnical wrote,
never a text file, a foreign bag or a directory holding other files; a full disk leaves
nothing half-written; stale staging of killed writes is swept, a killed recording recovered.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore
from typer.testing import CliRunner

from omnical.bags.bag import read_bag, write_bag
from omnical.bags.baginfo import summarize_bag
from omnical.bags.mcapwrite import McapWriter
from omnical.bags.recorder import BagRecorder
from omnical.bags.sink import BagSink
from omnical.bags.staging import find_staging, sweep_staging
from omnical.cli.main import app
from omnical.errors import RecordingError
from omnical.recording.recording import RecordingBuilder

runner = CliRunner()
STORE = get_typestore(Stores.ROS2_HUMBLE)
T0 = 1_700_000_000_000_000_000


def _twist(vx: float) -> Any:
    vec = STORE.types["geometry_msgs/msg/Vector3"]
    return STORE.types["geometry_msgs/msg/Twist"](
        linear=vec(x=vx, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
    )


def _distance(beacon: int, d: float) -> Any:
    from omnical.bags.typestores import typestore

    return typestore(2).types["marvelmind_ros2_msgs/msg/BeaconDistance"](
        address_hedge=9, address_beacon=beacon, distance_m=d
    )


def _foreign_bag(path: Path, connections: list[tuple[str, str, list[tuple[int, Any]]]]) -> Path:
    """A ROS 2 MCAP bag written by rosbags itself (no omnical marker)."""
    from omnical.bags.typestores import typestore

    store = typestore(2)
    with Writer2(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, msgtype, messages in connections:
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for t_ns, message in messages:
                writer.write(conn, t_ns, store.serialize_cdr(message, msgtype))
    return path


def _cmd_vel_bag(path: Path, times: list[int], values: list[float]) -> Path:
    msgs = [(t, _twist(v)) for t, v in zip(times, values, strict=True)]
    return _foreign_bag(path, [("/cmd_vel", "geometry_msgs/msg/Twist", msgs)])


def _outcome(path: Path) -> str:
    """What every reader says: 'ok' or the one RecordingError line (never another error)."""
    results = []
    for read in (read_bag, summarize_bag):
        try:
            read(path)
            results.append("ok")
        except RecordingError as err:
            assert "\n" not in str(err)
            results.append("error")
    info = runner.invoke(app, ["info", str(path)])
    assert info.exit_code in (0, 2), info.output
    assert "Traceback" not in info.output
    if info.exit_code == 2:
        assert info.output.strip().splitlines()[-1].startswith("omnical: error:")
    return ",".join(results)


def test_huge_times_are_refused_with_a_reason(tmp_path: Path) -> None:
    bag = _cmd_vel_bag(tmp_path / "huge", [2**63 + k for k in range(3)], [0.1] * 3)
    for read in (read_bag, summarize_bag):
        with pytest.raises(RecordingError, match="2\\^63 ns"):
            read(bag)
    result = runner.invoke(app, ["info", str(bag)])
    assert result.exit_code == 2 and "2^63 ns" in result.output


def test_backward_duplicated_and_non_finite_rows_are_cleaned_with_counts(tmp_path: Path) -> None:
    times = [T0 + 3, T0 + 1, T0 + 1, T0 + 2, T0 + 4, T0 + 5]
    values = [0.1, 0.2, 0.2, float("nan"), 1e300, 0.3]
    recording = read_bag(_cmd_vel_bag(tmp_path / "dirty", times, values))
    table = recording.topic("/cmd_vel")
    assert table.t_ns.tolist() == [T0 + 1, T0 + 3, T0 + 5]
    assert np.isfinite(table["vx_mps"]).all()
    notes = " | ".join(recording.notes)
    assert "1 message(s) out of time order" in notes
    assert "1 duplicated message(s) dropped" in notes
    assert "2 message(s) with non-finite or out-of-range values dropped" in notes
    result = runner.invoke(app, ["export", str(tmp_path / "dirty"), "--out", str(tmp_path / "e")])
    assert result.exit_code == 0
    assert "omnical: warning: /cmd_vel: 1 duplicated message(s) dropped" in result.output


def test_nan_and_negative_distances_are_dropped(tmp_path: Path) -> None:
    msgs = [(T0 + k, _distance(1 + k % 4, d)) for k, d in enumerate([1.0, np.nan, -2.0, 3.0])]
    bag = _foreign_bag(
        tmp_path / "ranges",
        [("/hedge/beacon_raw_distance", "marvelmind_ros2_msgs/msg/BeaconDistance", msgs)],
    )
    recording = read_bag(bag)
    assert recording.topic("/beacon_raw_distance")["distance_m"].tolist() == [1.0, 3.0]
    assert any("2 message(s)" in n for n in recording.notes)


def test_locate_says_the_distances_it_drops(tmp_path: Path) -> None:
    """Found by a new user: locate dropped NaN distances without a word (evaluate and export
    warn), and with every one unusable said the recording had none while info counted them."""
    topic, msgtype = "/hedge/beacon_raw_distance", "marvelmind_ros2_msgs/msg/BeaconDistance"
    for name, values in (("some", [1.0, np.nan, -2.0, 3.0]), ("all", [np.nan, np.inf] * 2)):
        msgs = [(T0 + k, _distance(1 + k % 4, d)) for k, d in enumerate(values)]
        bag = _foreign_bag(tmp_path / name, [(topic, msgtype, msgs)])
        result = runner.invoke(app, ["locate", str(bag), "--out", str(tmp_path / f"{name}.csv")])
        assert "Traceback" not in result.output
        said = result.stderr.splitlines()
        if name == "some":  # whatever locate makes of the two left, it says what it dropped
            dropped = "/beacon_raw_distance: 2 message(s) with non-finite or out-of-range values"
            assert f"omnical: warning: {dropped} dropped" in said, result.output
        else:
            assert result.exit_code == 2, result.output
            dropped = "/beacon_raw_distance: 4 message(s) with non-finite or out-of-range values"
            assert said == [f"omnical: error: all: nothing to multilaterate: {dropped} dropped"]


def test_info_on_a_bag_of_unknown_topics_lists_them_and_says_so(tmp_path: Path) -> None:
    string = STORE.types["std_msgs/msg/String"]
    bag = _foreign_bag(
        tmp_path / "foreign",
        [
            ("/chatter", "std_msgs/msg/String", [(T0 + k * 10**8, string(data="hi")) for k in range(5)]),
            ("/wheel_vel", "geometry_msgs/msg/Twist", [(T0 + k, _twist(0.1)) for k in range(3)]),
        ],
    )  # fmt: skip
    summary = summarize_bag(bag)
    assert summary.understood_nothing
    assert {(c.topic, c.count) for c in summary.connections} == {("/chatter", 5), ("/wheel_vel", 3)}
    result = runner.invoke(app, ["info", str(bag)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    assert "/chatter" in result.output and "std_msgs/String" in result.output
    assert "10.0" in result.output  # its rate
    assert "omnical understands none of these topics" in result.output
    export = runner.invoke(app, ["export", str(bag), "--out", str(tmp_path / "x")])
    assert export.exit_code == 2 and "nothing to export" in export.output


def test_info_lists_every_topic_with_type_count_rate_span_and_its_commands(
    tmp_path: Path,
) -> None:
    string = STORE.types["std_msgs/msg/String"]
    bag = _foreign_bag(
        tmp_path / "mixed",
        [
            ("/cmd_vel", "geometry_msgs/msg/Twist", [(T0 + k * 10**8, _twist(0.1)) for k in range(11)]),
            ("/chatter", "std_msgs/msg/String", [(T0 + k * 10**9, string(data="x")) for k in range(3)]),
        ],
    )  # fmt: skip
    result = runner.invoke(app, ["info", str(bag)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    lines = {line.split()[0]: line.split() for line in result.output.splitlines() if "/" in line}
    used_by = ["evaluate", "calibrate"]  # the commands that read /cmd_vel
    assert lines["/cmd_vel"][1:] == ["geometry_msgs/Twist", "11", "10.0", "0.00–1.00", *used_by]
    assert lines["/chatter"][1:] == ["std_msgs/String", "3", "1.0", "0.00–2.00", "no"]


def test_info_says_which_option_reads_a_motion_capture_topic(tmp_path: Path) -> None:
    t = STORE.types
    header = t["std_msgs/msg/Header"]
    stamp = t["builtin_interfaces/msg/Time"]

    def pose(k: int) -> Any:
        return t["geometry_msgs/msg/PoseStamped"](
            header=header(stamp=stamp(sec=k, nanosec=0), frame_id="world"),
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=0.1 * k, y=0.0, z=0.0),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )

    bag = _foreign_bag(
        tmp_path / "mocap",
        [("/robot/pose", "geometry_msgs/msg/PoseStamped", [(T0 + k * 10**8, pose(k)) for k in range(5)])],
    )  # fmt: skip
    result = runner.invoke(app, ["info", str(bag)], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    row = next(line for line in result.output.splitlines() if "/robot/pose" in line)
    assert row.split()[1:] == [
        "geometry_msgs/PoseStamped",
        "5",
        "10.0",
        "0.00–0.40",
        "with",
        "--reference-topic",
    ]


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    times=st.lists(
        st.one_of(
            st.integers(0, 2**64 - 1),
            st.integers(T0, T0 + 10**10),
            st.sampled_from([0, 2**63 - 1, 2**63, 2**64 - 1]),
        ),
        min_size=1,
        max_size=12,
    ),
    values=st.lists(
        st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, -0.0])),
        min_size=12,
        max_size=12,
    ),
    cut=st.one_of(st.none(), st.integers(0, 4000)),
)
def test_fuzzed_bags_end_in_a_result_or_one_recording_error(
    tmp_path_factory: pytest.TempPathFactory, times: list[int], values: list[float], cut: int | None
) -> None:
    where = tmp_path_factory.mktemp("fuzz")
    bag = _cmd_vel_bag(where / "bag", times, values[: len(times)])
    if cut is not None:
        mcap = bag / "bag.mcap"
        mcap.write_bytes(mcap.read_bytes()[:cut])
    outcome = _outcome(bag)
    if cut is None and max(times) < 2**63:
        assert outcome == "ok,ok"
        recording = read_bag(bag)
        if recording.has("/cmd_vel"):
            assert np.isfinite(recording.topic("/cmd_vel")["vx_mps"]).all()
        else:  # every row dropped: the notes say why, nothing silent
            assert recording.notes
    elif cut is None:
        assert outcome == "error,error"


def _tiny(path: Path) -> Path:
    builder = RecordingBuilder()
    for k in range(3):
        builder.add("/cmd_vel", T0 + k, vx_mps=0.1 * k, vy_mps=0.0, wz_radps=0.0)
    return write_bag(builder.build(), path)


def test_every_8_byte_flip_of_the_summary_is_a_recording_error(tmp_path: Path) -> None:
    """Found by a new user: some flips of an MCAP's summary ended in a traceback (rosbags read
    a record length from the file and raised OverflowError or MemoryError)."""
    from omnical.recording.recording import Recording, Table

    t_ns = T0 + np.arange(50, dtype=np.int64) * 20_000_000
    zeros = np.zeros(50)
    run = Recording(
        {"/cmd_vel": Table(t_ns, {"vx_mps": zeros + 0.1, "vy_mps": zeros, "wz_radps": zeros})}
    )
    mcap = next(write_bag(run, tmp_path / "run.mcap").glob("*.mcap"))
    data = mcap.read_bytes()
    summary_start = int.from_bytes(data[-28:-20], "little")  # the footer's first field
    raised = []
    for at in range(summary_start, len(data) - 37, 4):  # up to the footer
        flipped = bytearray(data)
        flipped[at : at + 8] = bytes(b ^ 0xFF for b in flipped[at : at + 8])
        mcap.write_bytes(bytes(flipped))
        for read in (read_bag, summarize_bag):
            try:
                read(mcap.parent)
            except RecordingError as err:
                assert "\n" not in str(err)
            except Exception as err:  # the test: nothing else may come out
                raised.append((at, read.__name__, type(err).__name__))
    assert raised == []


def test_out_of_memory_is_not_called_damage_and_a_folder_named_like_storage_is_no_storage(
    tmp_path: Path,
) -> None:
    """The review's findings: a MemoryError (a healthy bag too big for the memory left, or a
    corrupt length) was "complete but damaged"; a folder ``old.mcap`` kept inside a bag's
    folder (``ros2 bag record -o old.mcap``) made the bag "not a regular file"."""
    from omnical.bags.bag import unreadable

    bag = _cmd_vel_bag(tmp_path / "run", [T0, T0 + 1], [0.1, 0.2])
    said = str(unreadable(bag, MemoryError("Unable to allocate output buffer.")))
    assert said == (
        f"{bag}: cannot read bag (out of memory reading it: a corrupt record length, or less "
        "free memory than its records need)"
    )
    (bag / "old.mcap").mkdir()
    assert len(read_bag(bag).topic("/cmd_vel")) == 2


def test_overwrite_replaces_only_a_bag_omnical_wrote(tmp_path: Path) -> None:
    recording = read_bag(_tiny(tmp_path / "mine.mcap"))
    write_bag(recording, tmp_path / "mine.mcap", overwrite=True)  # ours: replaced
    _tiny(tmp_path / "mine1.bag")
    write_bag(recording, tmp_path / "mine1.bag", overwrite=True)
    text = tmp_path / "notes.bag"
    text.write_text("not a bag at all")
    with pytest.raises(RecordingError, match="not a ROS 1 bag"):
        write_bag(recording, text, overwrite=True)
    assert text.read_text() == "not a bag at all"
    foreign = _cmd_vel_bag(tmp_path / "foreign", [T0], [0.1])
    before = sorted((p.name, p.read_bytes()) for p in foreign.iterdir())
    with pytest.raises(RecordingError, match="omnical did not write"):
        write_bag(recording, foreign, overwrite=True)
    assert sorted((p.name, p.read_bytes()) for p in foreign.iterdir()) == before
    ros1 = tmp_path / "foreign1.bag"
    with Writer1(ros1) as writer:
        conn = writer.add_connection(
            "/cmd_vel", "geometry_msgs/msg/Twist", typestore=get_typestore(Stores.ROS1_NOETIC)
        )
        writer.write(
            conn,
            T0,
            get_typestore(Stores.ROS1_NOETIC).serialize_ros1(
                _twist(0.1), "geometry_msgs/msg/Twist"
            ),
        )
    with pytest.raises(RecordingError, match="omnical did not write"):
        write_bag(recording, ros1, overwrite=True)
    # a bag directory the user keeps other files in is never replaced
    mine = tmp_path / "mine"
    (mine / "calibration.yaml").write_text("keep me")
    with pytest.raises(RecordingError, match=r"not part of the bag \(calibration.yaml\)"):
        write_bag(recording, mine, overwrite=True)
    assert (mine / "calibration.yaml").read_text() == "keep me"
    assert read_bag(mine).has("/cmd_vel")


def test_simulate_checks_its_output_before_simulating(tmp_path: Path) -> None:
    text = tmp_path / "X.bag"
    text.write_text("my notes")
    for args in (
        ["--out", str(text), "--overwrite"],
        ["--out", "/proc/omnical-test/run.mcap"],
        ["--out", str(text)],
    ):
        result = runner.invoke(app, ["simulate", "no-such-script", *args])
        # the output is refused first: the script is not even looked at
        assert result.exit_code == 2, result.output
        assert "no-such-script" not in result.output
        assert result.output.count("\n") == 1
    assert text.read_text() == "my notes"


@pytest.mark.parametrize("name", ["fixes.xyz", "fixes.pdf", "fixes"])
def test_locate_refuses_a_plot_that_is_not_a_png_before_any_work(tmp_path: Path, name: str) -> None:
    """--plot f.xyz ended in matplotlib's traceback after the fixes were written."""
    bag = _foreign_bag(
        tmp_path / "ranges.mcap",
        [
            (
                "/hedge/beacon_raw_distance",
                "marvelmind_ros2_msgs/msg/BeaconDistance",
                [(T0, _distance(2, 1.0))],
            )
        ],
    )
    out, plot = tmp_path / "fixes.csv", tmp_path / name
    result = runner.invoke(app, ["locate", str(bag), "--out", str(out), "--plot", str(plot)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and "Warning" not in result.output
    assert result.stderr.splitlines() == [
        f"omnical: error: --plot {plot}: the figure is a PNG; give a file name ending in .png"
    ]
    assert not out.exists() and not plot.exists()


def test_recorder_overwrite_keeps_the_previous_bag_until_the_new_one_is_complete(
    tmp_path: Path,
) -> None:
    old = _tiny(tmp_path / "run.mcap")
    before = read_bag(old).topic("/cmd_vel").t_ns.tolist()
    recorder = BagRecorder(tmp_path / "run.mcap", overwrite=True, flush_period_s=0.0)
    with recorder:
        recorder.write_rows("/cmd_vel", [T0 + 99], vx_mps=[1.0], vy_mps=[0.0], wz_radps=[0.0])
        assert read_bag(old).topic("/cmd_vel").t_ns.tolist() == before  # still there
    assert read_bag(old).topic("/cmd_vel").t_ns.tolist() == [T0 + 99]
    assert recorder.kept_at == old
    assert not find_staging(old)


def test_a_full_disk_leaves_nothing_half_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    old = _tiny(tmp_path / "run.mcap")
    before = sorted((p.name, p.read_bytes()) for p in old.iterdir())
    recording = read_bag(old)

    def full(*args: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(BagSink, "write_messages", full)  # ROS 1, and rosbags' ROS 2 writer
    monkeypatch.setattr(McapWriter, "write_streams", full)  # omnical's bulk ROS 2 writer
    with pytest.raises(RecordingError, match="No space left on device"):
        write_bag(recording, old, overwrite=True)
    with pytest.raises(RecordingError, match="No space left on device"):
        write_bag(recording, old, overwrite=True, writer="rosbags")
    with pytest.raises(RecordingError, match="No space left on device"):
        write_bag(recording, tmp_path / "new.bag")
    assert sorted((p.name, p.read_bytes()) for p in old.iterdir()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no staging, no new.bag


def _dead_pid() -> int:
    """The id of a process that has ended (and been reaped)."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_staging_is_swept_and_a_killed_recording_recovered(tmp_path: Path) -> None:
    dead = _dead_pid()
    target = tmp_path / "run"
    stale = tmp_path / f".run.omnical-write-{dead}-abc"
    (stale / "run").mkdir(parents=True)
    (stale / "run" / "run.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\0" * 1000)
    live = tmp_path / ".run.omnical-write-1-def"  # pid 1 is alive: a concurrent writer
    live.mkdir()
    # a recorder killed mid-run: its staging holds every flushed chunk
    recorder = BagRecorder(target.with_suffix(".mcap"), flush_period_s=0.0)
    recorder.open()
    recorder.write_rows("/cmd_vel", [T0, T0 + 1], vx_mps=[0.1, 0.2], vy_mps=[0, 0], wz_radps=[0, 0])
    recorder.flush()
    sink = recorder._sink
    assert sink is not None
    sink.abort()
    staging = sink.location.parent
    killed = staging.with_name(staging.name.replace(f"-{os.getpid()}-", f"-{dead}-"))
    staging.rename(killed)
    os.utime(stale, (1e9, 1e9))  # killed long ago
    unfinished = sweep_staging(target)
    # nothing a killed writer left is removed (it holds what was recorded), nor a live one's
    assert stale.exists() and live.exists() and killed.exists()
    assert [s.path for s in unfinished] == [stale, killed]  # oldest first
    result = runner.invoke(app, ["recover", str(tmp_path / "run.mcap")])
    assert result.exit_code == 0, result.output
    assert "recovered 2 messages" in result.output and "1 older ones left there" in result.output
    assert read_bag(tmp_path / "run.recovered").topic("/cmd_vel")["vx_mps"].tolist() == [0.1, 0.2]
    assert not killed.exists()
    again = runner.invoke(app, ["recover", str(tmp_path / "run.mcap")])  # the older one: garbage
    assert again.exit_code == 2 and str(stale) in " ".join(again.output.split()), again.output


@pytest.mark.parametrize("name", ["run.mcap", "run.bag"])
def test_recover_leaves_a_complete_bag_alone_and_salvages_a_cut_one(
    tmp_path: Path, name: str
) -> None:
    """Found by a new user: recover on a complete bag copied it to RUN.recovered saying it had
    'recovered' it. A complete one is said to be so, nothing written; the same file cut in
    half is salvaged."""
    from omnical.bags.recover import storage_file

    builder = RecordingBuilder()
    t = np.arange(2000, dtype=np.int64) * 10_000_000
    builder.add_many(
        "/cmd_vel", t, vx_mps=np.ones(2000), vy_mps=np.zeros(2000), wz_radps=np.zeros(2000)
    )
    bag = write_bag(builder.build(), tmp_path / name)
    before = sorted(p.name for p in tmp_path.rglob("*"))
    result = runner.invoke(app, ["recover", str(bag)])
    assert result.exit_code == 0, result.output
    assert "is complete (closed with its index): nothing to recover" in result.output
    assert sorted(p.name for p in tmp_path.rglob("*")) == before
    file = storage_file(bag)
    assert file is not None
    data = file.read_bytes()
    # cut in half; and cut inside its index (a ROS 1 bag's header already points there)
    index_at = data.rfind(b"op=\x07") if name.endswith(".bag") else len(data) - 40
    for i, size in enumerate((len(data) // 2, index_at + 20)):
        cut = tmp_path / f"cut{i}{file.suffix}"
        cut.write_bytes(data[:size])
        result = runner.invoke(app, ["recover", str(cut)])
        assert result.exit_code == 0, result.output
        assert result.output.startswith("recovered "), (size, len(data), result.output)

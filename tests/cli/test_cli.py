"""The CLI as a user drives it: simulate, info, export, locate, evaluate, demo, and bad input."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from typer.testing import CliRunner

from omnical.cli.main import app

runner = CliRunner()

DOCUMENTED = {
    "/cmd_vel": "geometry_msgs/msg/Twist",
    "/odom": "nav_msgs/msg/Odometry",
    "/imu": "sensor_msgs/msg/Imu",
    "/ground_truth": "nav_msgs/msg/Odometry",
    "/omnical/events": "std_msgs/msg/String",
    "/hedge_pos_ang": "marvelmind_ros2_msgs/msg/HedgePositionAngle",
    "/beacon_raw_distance": "marvelmind_ros2_msgs/msg/BeaconDistance",
    "/beacons_pos_a": "marvelmind_ros2_msgs/msg/BeaconPositionAddressed",
    "/hedge_quality": "marvelmind_ros2_msgs/msg/HedgeQuality",
}


@pytest.fixture(scope="module")
def run_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "run.mcap"
    result = runner.invoke(app, ["simulate", "tour", "--seed", "3", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "" not in result.output.splitlines()  # piped, no bar: not a blank line either
    return out


def test_simulated_bag_opens_with_anyreader(run_bag: Path) -> None:
    bag_dir = run_bag.with_suffix("")
    with AnyReader([bag_dir]) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert topics == DOCUMENTED
    assert counts["/odom"] > 3000
    assert counts["/beacon_raw_distance"] > 3 * counts["/hedge_pos_ang"] - counts["/hedge_pos_ang"]


def test_info(run_bag: Path) -> None:
    result = runner.invoke(app, ["info", str(run_bag)])
    assert result.exit_code == 0, result.output
    assert "/hedge_pos_ang" in result.output
    match = re.search(r"distance travelled \(odometry\): ([0-9.]+) m", result.output)
    assert match is not None, result.output
    assert float(match.group(1)) == pytest.approx(9.0, abs=0.1)  # the tour drives 9 m


@pytest.mark.parametrize("fmt", ["csv", "tum"])
def test_export(run_bag: Path, tmp_path: Path, fmt: str) -> None:
    result = runner.invoke(app, ["export", str(run_bag), "--format", fmt, "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    files = sorted(p.name for p in tmp_path.iterdir())
    assert ("odom.csv" if fmt == "csv" else "odom.tum") in files


@pytest.mark.parametrize("method", ["lsq", "robust"])
def test_locate(run_bag: Path, tmp_path: Path, method: str) -> None:
    out = tmp_path / "fixes.csv"
    plot = tmp_path / "fixes.png" if method == "robust" else None
    args = ["locate", str(run_bag), "--method", method, "--out", str(out)]
    result = runner.invoke(app, args + (["--plot", str(plot)] if plot else []))
    assert result.exit_code == 0, result.output
    assert f"wrote {out}: " in result.output and " fixes ok " in result.output
    assert out.read_text().count("\n") > 100
    assert plot is None or plot.stat().st_size > 1000


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["simulate", "tour", "--robot", "nope", "--out", "x.mcap"], "unknown robot preset 'nope'"),
        (["simulate", "missing.yaml", "--out", "x.mcap"], "missing.yaml: cannot read"),
        (["info", "does-not-exist.mcap"], "does-not-exist"),
        (
            ["export", "does-not-exist.mcap", "--format", "xml", "--out", "d"],
            "--format: unknown value 'xml'; choose csv or tum",
        ),
        (
            ["locate", "does-not-exist.mcap", "--method", "magic", "--out", "f.csv"],
            "--method: unknown value 'magic'; choose robust, lsq or grid",
        ),
        (
            ["evaluate", "does-not-exist.mcap", "--align", "SE2", "--out", "d"],
            "--align: unknown value 'SE2'; choose none, origin or se2",
        ),
        (["locate", "does-not-exist.mcap", "--out", "f.csv"], "does-not-exist.mcap: no such bag"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    args: list[str], needle: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # two cases in a real process (stderr as a shell sees it), the others in-process, where the
    # same handlers print the same line
    if "nope" in args or needle.endswith("no such bag"):
        proc = subprocess.run(
            [sys.executable, "-m", "omnical.cli.main", *args],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            check=False,
        )
        status, stderr = proc.returncode, proc.stderr
    else:
        monkeypatch.chdir(tmp_path)
        result = runner.invoke(app, args)
        status, stderr = result.exit_code, result.stderr
    assert status == 2, stderr
    assert needle in stderr
    assert "Traceback" not in stderr
    assert len(stderr.strip().splitlines()) == 1


def test_bad_script_and_existing_output(tmp_path: Path, run_bag: Path) -> None:
    script = tmp_path / "s.yaml"
    script.write_text("steps:\n  - move: {vx_mps: 5.0, duration_s: 3}\n")
    result = runner.invoke(app, ["simulate", str(script), "--out", str(tmp_path / "o.mcap")])
    assert result.exit_code == 2
    result = runner.invoke(app, ["simulate", "tour", "--out", str(run_bag)])
    assert result.exit_code == 2
    assert not (tmp_path / "o").exists()


def test_truncated_bag_is_reported(tmp_path: Path, run_bag: Path) -> None:
    src = run_bag.with_suffix("") / "run.mcap"
    cut = tmp_path / "cut"
    cut.mkdir()
    data = src.read_bytes()
    (cut / "cut.mcap").write_bytes(data[: len(data) // 2])
    (cut / "metadata.yaml").write_text(
        (run_bag.with_suffix("") / "metadata.yaml").read_text().replace("run.mcap", "cut.mcap")
    )
    result = runner.invoke(app, ["info", str(cut)])
    assert result.exit_code == 2


def test_evaluate_against_ground_truth_and_csv(run_bag: Path, tmp_path: Path) -> None:
    import json

    from omnical.bags.bag import read_bag

    result = runner.invoke(app, ["evaluate", str(run_bag), "--out", str(tmp_path / "ev")])
    assert result.exit_code == 0, result.output
    metrics = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert set(metrics) == {
        "odometry",
        "ips",
        "multilateration",
        "smoothed",
    }  # ground truth is the reference
    assert set(metrics["odometry"]) == {"rmse_m", "rmse_x_m", "rmse_y_m", "max_m", "final_m"}
    assert (tmp_path / "ev" / "path.png").is_file()
    rec = read_bag(run_bag)
    gt = rec.topic("/ground_truth")
    t = gt.t_s(rec.start_ns)
    ref = tmp_path / "ref.csv"
    ref.write_text(
        "t_s,x_m,y_m\n"
        + "".join(f"{a},{b},{c}\n" for a, b, c in zip(t, gt["x_m"], gt["y_m"], strict=True))
    )
    result = runner.invoke(
        app,
        [
            "evaluate",
            str(run_bag),
            "--reference",
            str(ref),
            "--align",
            "none",
            "--no-figures",
            "--out",
            str(tmp_path / "ev2"),
        ],
    )
    assert result.exit_code == 0, result.output
    metrics = json.loads((tmp_path / "ev2" / "metrics.json").read_text())
    assert metrics["ground_truth"]["rmse_m"] < 1e-6
    ref.write_text("t_s,x_m\n0,1\n")
    result = runner.invoke(
        app, ["evaluate", str(run_bag), "--reference", str(ref), "--out", str(tmp_path / "ev3")]
    )
    assert result.exit_code == 2


def test_simulate_uncompressed_and_info_from_the_index(tmp_path: Path) -> None:
    """Default bags are zstd-compressed MCAP; --uncompressed is bigger; info says the same."""
    sizes, infos = {}, {}
    for label, extra in (("zstd", []), ("plain", ["--uncompressed"])):
        out = tmp_path / label / "run.mcap"
        args = ["simulate", "straight-10m", "--seed", "1", "--out", str(out), *extra]
        result = runner.invoke(app, args)
        assert result.exit_code == 0, result.output
        bag = out.with_suffix("")
        sizes[label] = (bag / "run.mcap").stat().st_size
        info = runner.invoke(app, ["info", str(bag)])
        assert info.exit_code == 0, info.output
        # the path is the table's centred title: compare the lines without their padding
        infos[label] = [line.strip() for line in info.output.replace(str(bag), "BAG").splitlines()]
    assert sizes["plain"] > 3 * sizes["zstd"]
    assert infos["plain"] == infos["zstd"]
    assert any(line.startswith("distance travelled (odometry)") for line in infos["zstd"])

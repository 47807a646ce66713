"""``--monitor PORT`` on ``ros2 correct``, ``ros2 locate`` and ``ros2 map`` (issue 26).

Real processes: ``omnical monitor``, ``omnical ros2 twin`` (the odometry and the hedgehog's pty)
and the three commands on a private domain; a page's socket reads what the monitor serves.
"""

from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from ros2_env import RosProcess, needs_ros2, omnical_command, private_domain_id, ros_env

from omnical.calibration.factors_io import write_factors
from omnical.kinematics.correction import CorrectionFactors

pytestmark = [needs_ros2, pytest.mark.alone]  # wall clock, five processes


def _monitor_procs() -> Any:
    """tests/web/monitor_procs.py (another test directory's helper, by its path)."""
    path = Path(__file__).parents[1] / "web" / "monitor_procs.py"
    spec = importlib.util.spec_from_file_location("monitor_procs", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("monitor_procs", module)
    spec.loader.exec_module(module)
    return module


def test_correct_locate_and_map_stream_to_the_monitor(tmp_path: Path) -> None:
    from omnical.web.wsclient import WebSocketClient

    env = ros_env(private_domain_id(__name__))
    factors = tmp_path / "factors.yaml"
    write_factors(factors, CorrectionFactors.seed000_table2())
    mon = _monitor_procs().start_monitor()
    procs: list[RosProcess] = []
    try:
        twin = RosProcess(omnical_command("ros2", "twin"), env)
        procs.append(twin)
        line = twin.readline(30.0)
        assert line.startswith("hedgehog: "), (line, twin.stop())
        pty = line.split(": ", 1)[1].strip()
        port = str(mon.port)
        for args in (
            ("correct", "--factors", str(factors)),
            ("locate", "--hedge", f"serial:{pty}"),
            ("map", "lab-8x6"),
        ):
            procs.append(RosProcess(omnical_command("ros2", *args, "--monitor", port), env))
        page = WebSocketClient.connect("127.0.0.1", mon.port, "/ws")
        page.sock.settimeout(5)
        got: dict[str, Any] = {}
        sources: set[str] = set()
        deadline = time.monotonic() + 60  # four ROS 2 processes start, each re-executed
        while not {"odom", "fix", "map", "beacons"} <= got.keys():
            assert time.monotonic() < deadline, (sorted(got), sources)
            assert all(p.proc.poll() is None for p in procs), [p.stop() for p in procs]
            message = json.loads(page.recv_text())
            for frame in message if isinstance(message, list) else [message]:  # batched or one
                got[frame["s"]] = frame["d"]
                if frame["s"] == "source":
                    sources.add(frame["d"]["source"])
        page.close()
    finally:
        stops = [p.stop() for p in reversed(procs)]
        mon.proc.stop()
    # odometry only from correct, fixes and beacons only from locate, a map only from map
    assert sources <= {"omnical ros2 correct", "omnical ros2 locate", "omnical ros2 map"}
    odom, fix = got["odom"], got["fix"]
    assert odom["x"] and abs(odom["t"][-1] - time.time()) < 30  # the twin's wall-clock stamps
    assert fix["x"] and 0.5 < fix["x"][-1] < 3.5 and 0.5 < fix["y"][-1] < 3.0  # near (1.5, 1.2)
    assert got["map"]["width"] > 0 and got["map"]["resolution"] > 0
    assert len(got["beacons"]["beacons"]) >= 4  # streamed by the hedgehog, latched
    for status, _, err in stops:
        assert status in (0, 130, -9) and "Traceback" not in err, err

"""The monitor's wire format: ``--monitor`` targets, rows as frames, thinning, events, the map."""

from __future__ import annotations

import base64
import json
import math

import numpy as np
import pytest

from omnical.errors import ConfigError
from omnical.recording.topics import CMD_VEL, EVENTS, HEDGE_POS_ANG, IMU, ODOM
from omnical.web.protocol import (
    decimate,
    dumps,
    event_payload,
    is_loopback,
    map_payload,
    parse_monitor_target,
    rows_to_frames,
)


def test_monitor_targets() -> None:
    assert parse_monitor_target("8765") == parse_monitor_target("127.0.0.1:8765")
    t = parse_monitor_target("10.0.0.2:9000")
    assert (t.host, t.port, t.token) == ("10.0.0.2", 9000, None)
    u = parse_monitor_target("http://10.0.0.2:9001/?token=abc_D-1")
    assert (u.host, u.port, u.token) == ("10.0.0.2", 9001, "abc_D-1")
    assert u.ingest_path == "/ingest?token=abc_D-1"
    assert parse_monitor_target("[::1]:8000").host == "::1"
    for bad in ("", "x", "host:", "70000", "0", "ftp://h:1/"):
        with pytest.raises(ConfigError, match="--monitor"):
            parse_monitor_target(bad)


def test_loopback() -> None:
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.4")
    assert not is_loopback("example.org")


def test_decimate_keeps_at_most_the_rate_and_the_last_row() -> None:
    t = np.arange(0.0, 2.0, 0.005)  # 200 Hz for 2 s
    keep = decimate(t, 50.0)
    assert keep[0] == 0 and keep[-1] == len(t) - 1
    gaps = np.diff(t[keep])[:-1]
    assert gaps.min() >= 0.02 - 1e-9
    assert 99 <= len(keep) <= 101
    assert list(decimate(np.array([0.0, 0.001]), 50.0)) == [0, 1]


def test_odometry_rows_become_one_thinned_frame() -> None:
    n = 100
    t_ns = 1_700_000_000_000_000_000 + np.arange(n) * 5_000_000  # 200 Hz
    cols = {
        c: np.linspace(0, 1, n) for c in ("x_m", "y_m", "yaw_rad", "vx_mps", "vy_mps", "wz_radps")
    }
    [(stream, data)] = rows_to_frames(ODOM, t_ns, cols)
    assert stream == "odom"
    assert len(data["t"]) == len(data["x"]) == len(data["vx"]) == 26  # 50 Hz over 0.5 s, + last
    assert data["x"][-1] == 1.0
    assert data["t"][0] == pytest.approx(1.7e9)
    assert rows_to_frames(IMU, t_ns, {}) == []
    assert rows_to_frames(ODOM, t_ns[:0], {k: v[:0] for k, v in cols.items()}) == []


def test_fixes_keep_every_row_and_their_flags() -> None:
    t_ns = np.array([1, 2, 3]) * 10**9
    cols = {"address": [10] * 3, "timestamp_ms": [0] * 3, "x_m": [1.0, 2.0, 3.0],
            "y_m": [0.0, 0.5, 1.0], "z_m": [0.4] * 3, "flags": [2, 3, 2], "angle_deg": [0.0] * 3}  # fmt: skip
    [(stream, data)] = rows_to_frames(HEDGE_POS_ANG, t_ns, cols)
    assert stream == "fix" and data["flags"] == [2, 3, 2] and data["x"] == [1.0, 2.0, 3.0]
    [(_, cmd)] = rows_to_frames(
        CMD_VEL, t_ns, {"vx_mps": [0.1] * 3, "vy_mps": [0.0] * 3, "wz_radps": [0.0] * 3}
    )
    assert cmd["vx"] == [0.1] * 3


def test_events_are_read_and_levelled() -> None:
    texts = np.array(
        [json.dumps({"omnical": "installed_factors", "factors": {"scale_x": 1.0}}),
         "hedgehog silent for 0.6 s", "safety stop: vehicle controller"], dtype=object,
    )  # fmt: skip
    frames = rows_to_frames(EVENTS, np.array([1, 2, 3]) * 10**9, {"text": texts})
    assert [f[1]["level"] for f in frames] == ["info", "warning", "abort"]
    assert frames[0][1]["kind"] == "installed_factors"
    assert "scale_x" in frames[0][1]["text"]
    assert event_payload(5.0, "plain line")["text"] == "plain line"
    # a navigate target reads as words, not raw JSON (audit item 7)
    target = json.dumps({"omnical": "target", "target": {"controller": "pure-pursuit", "index": 1},
                         "x": 2.123456})  # fmt: skip
    assert event_payload(5.0, target)["text"] == (
        "target: target (controller pure-pursuit, index 1), x 2.123"
    )


def test_json_has_no_nan() -> None:
    text = dumps({"a": [1.0, math.nan, math.inf], "b": {"c": -math.inf}})
    assert json.loads(text) == {"a": [1.0, None, None], "b": {"c": None}}


def test_map_payload_round_trips_the_cells() -> None:
    cells = np.array([[0, 100, -1], [100, 0, 0]], dtype=np.int8)
    m = map_payload(cells, 0.05, (-1.0, 2.0, 0.0))
    raw = np.frombuffer(base64.b64decode(m["cells"]), dtype=np.uint8).reshape(2, 3)
    assert raw.tolist() == [[0, 100, 255], [100, 0, 0]]
    assert (m["width"], m["height"], m["resolution"], m["origin"]) == (3, 2, 0.05, [-1.0, 2.0, 0.0])

"""Evaluation on hostile input: one clear error, strict JSON, never a StopIteration or Infinity."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from omnical.errors import ConfigError, RecordingError
from omnical.evaluation.metrics import TrackingMetrics, metrics_json, track_recording
from omnical.evaluation.reference_input import load_reference
from omnical.recording.recording import Recording, RecordingBuilder


def test_metrics_json_stays_strict_json() -> None:
    text = metrics_json({"ips": TrackingMetrics(math.inf, math.inf, 0.5, math.nan, 0.1, 3)})
    back = json.loads(text)  # strict: no Infinity / NaN tokens
    assert back["ips"]["rmse_m"] is None and back["ips"]["max_m"] is None
    assert back["ips"]["rmse_y_m"] == 0.5
    assert "Infinity" not in text and "NaN" not in text


def test_a_recording_with_no_estimate_is_refused_with_a_reason() -> None:
    builder = RecordingBuilder()
    t = np.arange(10, dtype=np.int64) * 100_000_000
    builder.add_many("/cmd_vel", t, vx_mps=np.zeros(10), vy_mps=np.zeros(10), wz_radps=np.zeros(10))
    recording = builder.build()
    reference = (np.array([0.0, 1.0]), np.array([[0.0, 0.0], [1.0, 0.0]]))
    with pytest.raises(RecordingError, match="nothing to evaluate"):
        track_recording(recording, reference)


@pytest.mark.parametrize(
    ("row", "needle"),
    [
        ("1,1e300,0", "line 3: t_s must lie within"),
        ("1,0,-1e5", "line 3: t_s must lie within"),
        ("1,nan,0", "line 3: x_m: not a finite number"),
        ("0.5,0,0", "line 3: t_s does not increase"),
    ],
)
def test_reference_csv_values_out_of_any_room_are_refused(
    tmp_path: Path, default_tour: Recording, row: str, needle: str
) -> None:
    path = tmp_path / "ref.csv"
    path.write_text(f"t_s,x_m,y_m\n0.5,0,0\n{row}\n2,1,1\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=needle):
        load_reference(str(path), default_tour)


_CELLS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-(10**30), max_value=10**30).map(str),
    st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=8),
    st.just(""),
)


@settings(
    max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    header=st.sampled_from(["t_s,x_m,y_m", "x_m,t_s,y_m", "t_s,x_m", "", "t_s,x_m,y_m,extra"]),
    rows=st.lists(st.lists(_CELLS, min_size=0, max_size=4), max_size=6),
    raw=st.binary(max_size=64),
)
def test_any_reference_csv_loads_or_gives_one_config_error(
    tmp_path: Path, default_tour: Recording, header: str, rows: list[list[str]], raw: bytes
) -> None:
    path = tmp_path / "ref.csv"
    text = "\n".join([header, *(",".join(r) for r in rows)]) + "\n"
    path.write_bytes(text.encode("utf-8", "surrogatepass") + raw)
    try:
        ref = load_reference(str(path), default_tour)
    except ConfigError as err:
        assert "\n" not in str(err)
        return
    assert np.all(np.isfinite(ref.t_s)) and np.all(np.isfinite(ref.xy_m))
    assert np.all(np.diff(ref.t_s) > 0)


@pytest.mark.parametrize(
    ("bad_line", "reason"),
    [
        ("1.0 0.1 0 0 0 0 0 0", "qx qy qz qw must be a unit quaternion (all zero: no orientation)"),
        ("1.0 0.1 0 0 0 0 0 2", "qx qy qz qw must be a unit quaternion (norm 2)"),
        ("1.0 0.1 0 0 1e300 0 0 1", "qx qy qz qw must be a unit quaternion (a component beyond"),
        ("1.0 0.1 0 0 0 0 0 nan", "need finite numbers, got '1.0 0.1 0 0 0 0 0 nan'"),
    ],
)
def test_a_tum_quaternion_that_is_no_rotation_is_refused_with_its_line(
    tmp_path: Path, default_tour: Recording, bad_line: str, reason: str
) -> None:
    """All-zero quaternions gave yaw 0 silently (exit 0); now the file and the line."""
    from typer.testing import CliRunner

    from omnical.bags.bag import write_bag
    from omnical.cli.main import app

    bag = write_bag(default_tour, tmp_path / "tour.mcap")
    ref = tmp_path / "ref.tum"
    ref.write_text(f"# t x y z qx qy qz qw\n0.0 0 0 0 0 0 0 1\n{bad_line}\n2.0 0.2 0 0 0 0 0 1\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = CliRunner().invoke(
            app, ["evaluate", str(bag), "--reference", str(ref), "-o", str(tmp_path / "ev")]
        )
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "Warning" not in res.output
    (line,) = res.stderr.splitlines()
    assert line.startswith(f"omnical: error: {ref}: line 3: {reason}"), line
    assert not (tmp_path / "ev").exists()


def test_tum_quaternions_are_normalised_before_their_yaw(
    tmp_path: Path, default_tour: Recording
) -> None:
    ref = tmp_path / "ref.tum"
    half = 0.3  # yaw 0.6 rad; the second pose's quaternion written 0.5 % long
    ref.write_text(
        f"0.0 0 0 0 0 0 {math.sin(half):.9f} {math.cos(half):.9f}\n"
        f"1.0 0 0 0 0 0 {1.005 * math.sin(half):.9f} {1.005 * math.cos(half):.9f}\n"
    )
    yaw = load_reference(str(ref), default_tour).yaw_rad
    assert yaw is not None
    np.testing.assert_allclose(yaw, [0.6, 0.6], atol=1e-8)

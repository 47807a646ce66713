"""The calibration campaign (seed 000 Figure 7) on the twin, its measures and its report.

The twin is ``default_twin(rosy-mecanum)``: seed 000 Table 2 as the truth (forward +0.0072,
reverse −0.00009, left +0.0389, right −0.0277 rad/m), 5 % NLOS range outliers, slip, backlash,
the hedgehog 5 cm off the robot centre. The campaign estimates from /cmd_vel, /odom and the
Marvelmind raw distances only; the measures use the twin's ground truth.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pytest

from omnical.bags.bag import read_bag
from omnical.calibration.campaign import (
    Bench,
    CampaignProgress,
    CampaignResult,
    Tolerance,
    estimate_factors,
    installed_from_recordings,
    run_campaign,
    with_installed_event,
)
from omnical.calibration.factors_io import read_factors
from omnical.calibration.measures import (
    MEASURE_SPECS,
    leg_measures,
    measure_scripts,
    measures_from_recordings,
)
from omnical.calibration.procedures.scripts import hull_margin_m, nominal_path
from omnical.errors import CalibrationError, ConfigError
from omnical.experiment.script import parse_script
from omnical.ips.beacons import default_beacon_map
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import Factor
from omnical.recording.recording import Recording
from omnical.reports.campaign import CampaignFiles, write_campaign
from omnical.reports.markdown import MarkdownTable, Section, render_markdown
from omnical.reports.tables import factors_table, measures_table
from omnical.robot.loader import load_robot
from omnical.twin.bench import TwinBench, run_twin_campaign
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.session import simulate_run

ROBOT = load_robot("rosy-mecanum")
TWIN = default_twin(ROBOT)
TRUTH = TWIN.true_factors
SCALE_TOL = 0.005  # issue acceptance: each scaling within 0.5 %
CROSS_TOL = 1.5e-3  # and each cross-talk within 1.5 mrad/m


def assert_recovers_truth(factors: CorrectionFactors) -> None:
    rel = factors.scales / TRUTH.scales - 1.0
    cross = factors.crosstalks_rad_per_m - TRUTH.crosstalks_rad_per_m
    assert np.all(np.abs(rel) <= SCALE_TOL), rel
    assert np.all(np.abs(cross) <= CROSS_TOL), cross


@functools.cache
def campaign_without_files(seed: int) -> tuple[CampaignResult, tuple[CampaignProgress, ...]]:
    events: list[CampaignProgress] = []
    result = run_twin_campaign(ROBOT, TWIN, seed=seed, on_progress=events.append)
    return result, tuple(events)


@pytest.fixture(scope="module")
def campaign0() -> CampaignResult:
    return run_twin_campaign(ROBOT, TWIN, seed=0)


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory, campaign0: CampaignResult) -> CampaignFiles:
    out = tmp_path_factory.mktemp("campaign") / "calibration"
    return write_campaign(campaign0, out, ROBOT)


def _table_text(table: MarkdownTable) -> str:
    return render_markdown("t", [Section("s", (table,))], base_dir=".")


# ------------------------------------------------------------------------ issue acceptance


def test_campaign_recovers_table2_seed0(campaign0: CampaignResult) -> None:
    result = campaign0
    assert_recovers_truth(result.factors)
    assert result.converged
    assert 2 <= len(result.iterations) <= 4  # the first, from identity, cannot be within 0.3 %
    first = result.iterations[0]
    assert first.installed == CorrectionFactors()
    assert not first.converged
    assert first.change["scale_lateral"] == pytest.approx(0.13, abs=0.005)
    # each iteration starts from the totals of the one before (totals compose)
    for before, after in zip(result.iterations, result.iterations[1:], strict=False):
        assert after.installed == before.factors
    # the rotation stage ran before the translations, and its factor was installed for them
    assert first.translation.installed.scale_rotational == pytest.approx(
        first.rotation.factors.scale_rotational
    )
    for name, sigma in result.sigma.items():
        assert 0.0 < sigma < (0.003 if Factor(name).is_scale else 0.0008), name


def test_campaign_recovers_table2_seed1() -> None:
    result, _ = campaign_without_files(1)
    assert_recovers_truth(result.factors)
    assert result.converged
    assert set(result.procedure_runs) <= set(result.runs)
    assert len(result.runs) == len(result.procedure_runs) + 6  # the measures: 3 before, 3 after


def test_after_calibration_at_least_as_good_as_the_paper(campaign0: CampaignResult) -> None:
    for result in (campaign0, campaign_without_files(1)[0]):
        before, after = result.measures_before, result.measures_after
        assert before is not None and after is not None
        for spec in MEASURE_SPECS:
            assert spec.passes(after), (spec.label, spec.value(after))
            assert spec.value(after) < 0.25 * spec.value(before), spec.label
        # before calibration the twin shows what the paper saw (Table 2 as the truth)
        assert -27.0 < before.heading_error_deg < -21.0  # 1080°·(1 − 1/1.0236) = 24.9°
        assert before.longitudinal_error_m == pytest.approx(-10.0 * (1 - 1 / 1.02), abs=0.03)
        assert before.crosstalk_longitudinal_mrad_per_m == pytest.approx(7.2, abs=0.5)
        assert before.crosstalk_lateral_mrad_per_m == pytest.approx(38.9, abs=1.5)
        assert 0.2 < before.lateral_drift_m < 0.45


def test_validation_residual_is_small(campaign0: CampaignResult) -> None:
    validation = campaign0.validation
    assert validation is not None
    residual = validation.residual
    assert np.all(np.abs(residual.scales - 1.0) < 0.004)
    assert np.all(np.abs(residual.crosstalks_rad_per_m) < 0.0012)
    z = validation.z_scores()
    assert all(abs(v) < 4.0 for v in z.values())
    assert validation.estimate.installed == campaign0.factors


def test_progress_runs_rotation_first() -> None:
    _, events = campaign_without_files(1)
    steps = list(dict.fromkeys(e.step for e in events))
    assert steps[:4] == [
        "iteration 1: rotation procedure",
        "iteration 1: rotation analysis",
        "iteration 1: longitudinal procedure",
        "iteration 1: lateral procedure",
    ]
    assert "validation: analysis" in steps
    assert steps[-1] == "measures after: lateral"
    runs = [e for e in events if e.total_s > 0.0]
    assert all(0.0 <= e.done_s <= e.total_s for e in runs)
    assert max(e.total_s for e in runs) == pytest.approx(201.5, abs=1.0)  # lateral procedure


# ------------------------------------------------------------------------ files


def test_campaign_writes_its_files(campaign0: CampaignResult, files: CampaignFiles) -> None:
    written = campaign0
    out = files.out_dir
    assert files.report == out / "report.md" == files.files["report"]
    back = read_factors(out / "factors.yaml")
    assert back.factors == written.factors
    assert back.uncertainty is not None
    assert back.uncertainty.scale_lateral == pytest.approx(written.sigma["scale_lateral"])
    header = (out / "omnical_factors.h").read_text(encoding="utf-8")
    assert f"#define OMNICAL_SCALE_LATERAL {written.factors.scale_lateral:.6f}f" in header
    params = (out / "wheeltec_params.yaml").read_text(encoding="utf-8")
    assert "odom_y_scale" in params
    figures = sorted(p.name for p in (out / "figures").glob("*.png"))
    n = len(written.iterations)
    assert len(figures) == 3 * n + 3 + 1
    assert {"iter1-rotation.png", "validation-lateral.png", "measures.png"} <= set(figures)
    assert all((out / "figures" / f).stat().st_size > 20_000 for f in figures)
    bags = sorted(p.name for p in (out / "recordings").iterdir())
    assert len(bags) == 3 * n + 3


def test_report_has_table2_and_the_measures(files: CampaignFiles) -> None:
    text = files.report.read_text(encoding="utf-8")
    assert "| Lateral-left velocity to rotational | +0.03" in text
    assert "Truth (twin)" in text and "± 1σ" in text
    assert "| heading error after 3 turns | ° | 25.5 |" in text
    measures = text.split("## Before and after")[1].split("## Iterations")[0]
    assert measures.count("| yes |") == len(MEASURE_SPECS)
    assert "(figures/iter1-rotation.png)" in text
    assert "omnical calibrate estimate recordings/validation-rotation" in text
    assert "## Validation" in text and "## Iterations" in text


def test_offline_analysis_of_the_written_bags(
    campaign0: CampaignResult, files: CampaignFiles
) -> None:
    written, out = campaign0, files.out_dir
    bags = [
        read_bag(out / "recordings" / f"validation-{k}")
        for k in ("rotation", "longitudinal", "lateral")
    ]
    assert installed_from_recordings(bags) == written.factors
    estimate = estimate_factors(bags, hedge_offset_m=ROBOT.hedge_offset_m)
    assert estimate.installed == written.factors  # read from the bags' events
    assert_recovers_truth(estimate.factors)
    mixed = [read_bag(out / "recordings" / "iter1-rotation"), bags[0]]
    with pytest.raises(CalibrationError, match="different installed factors"):
        estimate_factors(mixed)


# ------------------------------------------------------------------------ pieces


def test_campaign_from_calibrated_robot_converges_at_once() -> None:
    start = TRUTH.with_values(scale_lateral=1.131, crosstalk_left_rad_per_m=0.0392)
    result = run_twin_campaign(
        ROBOT, TWIN.with_installed(start), seed=3, validate=False, measure=False
    )
    assert len(result.iterations) == 1 and result.converged
    assert result.initial == start
    assert_recovers_truth(result.factors)
    assert result.measures_before is None and result.validation is None


class CountingBench:
    """A bench of another kind: forwards to the twin and keeps what it was asked to run."""

    def __init__(self, inner: Bench) -> None:
        self.inner = inner
        self.calls: list[tuple[str, CorrectionFactors]] = []

    def run(self, script, installed, *, name, on_tick=None):  # type: ignore[no-untyped-def]
        self.calls.append((name, installed))
        return self.inner.run(script, installed, name=name, on_tick=on_tick)


def test_campaign_runs_on_any_bench() -> None:
    start = TRUTH.with_values(scale_lateral=1.131, crosstalk_left_rad_per_m=0.0392)
    bench = CountingBench(TwinBench(ROBOT, TWIN, seed=3))
    result = run_campaign(ROBOT, bench, installed=start, validate=False, measure=False)
    assert [name for name, _ in bench.calls] == [
        "iter1-rotation",
        "iter1-longitudinal",
        "iter1-lateral",
    ]
    assert bench.calls[0][1] == start  # the rotation ran with what was installed
    assert (
        bench.calls[1][1].scale_rotational == result.iterations[0].rotation.factors.scale_rotational
    )
    assert result.truth is None  # a bench does not tell the truth
    assert set(result.runs) == {"iter1-rotation", "iter1-longitudinal", "iter1-lateral"}


def test_tolerance() -> None:
    tol = Tolerance(scale_relative=0.002, crosstalk_rad_per_m=0.001)
    a = CorrectionFactors(1.0, 1.1, 1.0, 0.0, 0.0, 0.03, 0.0)
    b = a.with_values(scale_lateral=1.1 * 1.0019, crosstalk_left_rad_per_m=0.0309)
    assert tol.changes(a, b)["scale_lateral"] == pytest.approx(0.0019)
    assert tol.changes(a, b)["crosstalk_left_rad_per_m"] == pytest.approx(0.0009)
    assert tol.met(a, b)
    assert not tol.met(a, b.with_values(crosstalk_right_rad_per_m=-0.0011))
    with pytest.raises(ConfigError, match="tolerance"):
        Tolerance(scale_relative=0.0)
    with pytest.raises(ConfigError, match="max_iterations"):
        run_twin_campaign(ROBOT, TWIN, max_iterations=0)
    with pytest.raises(ConfigError, match="method"):
        run_twin_campaign(ROBOT, TWIN, method="magic")  # type: ignore[arg-type]


def _short_run(params: TwinParams, seed: int) -> Recording:
    data = {"steps": [{"hold": {"duration_s": 2}}, {"move": {"vx_mps": 0.2, "distance_m": 0.5}}]}
    return simulate_run(parse_script(data, ROBOT.limits), ROBOT, params, seed=seed)


def test_installed_event_round_trip(tmp_path: Path) -> None:
    from omnical.bags.bag import write_bag

    rec = _short_run(TWIN, 1)
    assert installed_from_recordings([rec]) is None
    factors = CorrectionFactors(1.01, 1.12, 1.02, 0.007, -0.0001, 0.039, -0.028)
    tagged = with_installed_event(rec, factors)
    back = read_bag(write_bag(tagged, tmp_path / "tagged.mcap"))
    assert installed_from_recordings([back]) == factors
    assert len(back.topic("/omnical/events")) == len(rec.topic("/omnical/events")) + 1
    with pytest.raises(CalibrationError, match="different installed factors"):
        installed_from_recordings([tagged, rec])


def test_measures_scripts_stay_inside_the_map() -> None:
    scripts = measure_scripts()
    assert set(scripts) == {"turns", "longitudinal", "lateral"}
    beacons = default_beacon_map()
    for data in scripts.values():
        script = parse_script(data, ROBOT.limits)
        real = nominal_path(script, TWIN.start_pose_map, true_factors=TRUTH)
        assert hull_margin_m(real, beacons) >= 0.35
    legs = [s["move"] for s in scripts["longitudinal"]["steps"] if "move" in s]
    assert [m["vx_mps"] for m in legs] == [0.25, -0.25, 0.25, -0.25]
    assert sum(m["distance_m"] for m in legs) == pytest.approx(10.0)
    with pytest.raises(CalibrationError, match="legs"):
        measure_scripts(legs=3)


def _measure_runs(params: TwinParams, seed: int) -> list[Recording]:
    scripts = measure_scripts()
    return [
        simulate_run(parse_script(scripts[k], ROBOT.limits), ROBOT, params, seed=seed + j)
        for j, k in enumerate(("turns", "longitudinal", "lateral"))
    ]


def test_measures_on_the_ideal_and_the_default_twin() -> None:
    ideal = measures_from_recordings(*_measure_runs(TwinParams.ideal_twin(), 5))
    assert abs(ideal.heading_error_deg) < 0.05
    assert abs(ideal.longitudinal_error_m) < 1e-3
    assert ideal.lateral_drift_m < 1e-3
    assert max(abs(v) for v in ideal.crosstalk_rad_per_m.values()) < 5e-5
    assert ideal.turns == pytest.approx(3.0, abs=0.01)  # the step turn ends on a 50 Hz tick
    assert ideal.longitudinal_distance_m == pytest.approx(10.0, abs=1e-3)
    runs = _measure_runs(TWIN, 7)
    legs = leg_measures(runs[2])
    assert [leg.kind for leg in legs] == ["left", "right", "left", "right"]
    left = legs[0]
    assert left.true_length_m == pytest.approx(2.5 / 1.13, rel=0.01)
    assert left.crosstalk_rad_per_m == pytest.approx(0.0389, abs=0.002)
    # turning CCW while moving left, the robot drifts backwards (−x) off its line
    assert left.sideways_error_m > 0.0 and left.end_error_body_m[0] < -0.05
    m = measures_from_recordings(*runs)
    assert m.crosstalk_rad_per_m["right"] == pytest.approx(-0.0277, abs=0.002)
    with pytest.raises(CalibrationError, match="ground_truth"):
        measures_from_recordings(runs[0].without("/ground_truth"), runs[1], runs[2])
    with pytest.raises(CalibrationError, match="no rotate_ccw or rotate_cw"):
        measures_from_recordings(runs[1], runs[1], runs[2])


def test_report_tables() -> None:
    sigma = dict.fromkeys(TRUTH.as_dict(), 0.0004) | {"scale_rotational": math.inf}
    table = _table_text(factors_table(TRUTH.with_values(scale_lateral=1.1311), sigma, TRUTH))
    lines = [line for line in table.splitlines() if line.startswith("|")]
    assert len(lines) == 2 + 7
    assert "| Lateral velocity | 1.13110 | 0.00040 | 1.13000 | +0.097 % | 1.1300 |" in table
    assert "| Rotational velocity | 1.02360 | not estimated |" in table
    assert "-0.02770" in table and "0.02770 (magnitude)" in table
    no_truth = _table_text(factors_table(TRUTH, sigma))
    assert "Truth" not in no_truth
    result, _ = campaign_without_files(1)
    assert result.measures_before is not None and result.measures_after is not None
    md = _table_text(measures_table(result.measures_before, result.measures_after))
    assert md.count("| yes |") == 5
    assert "| lateral cross-talk | mrad/m | 38 |" in md

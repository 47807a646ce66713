"""Seed 000 §3.2 calibration procedures on the twin: scripts, analyses, issue acceptance.

The twin is ``default_twin(rosy-mecanum)``: seed 000 Table 2 as the truth (forward +0.0072,
reverse −0.00009, left +0.0389, right −0.0277 rad/m), 5 % NLOS range outliers, random slip,
backlash, the hedgehog 5 cm off the robot centre. The analyses read /cmd_vel, /odom and the
Marvelmind raw distances only.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from omnical.calibration.procedures.analysis import ProcedureEstimate, analyse_procedures
from omnical.calibration.procedures.geometry import arc_length, fit_circle
from omnical.calibration.procedures.scripts import (
    hull_margin_m,
    lateral_procedure,
    longitudinal_procedure,
    nominal_path,
    rotation_procedure,
)
from omnical.calibration.procedures.segments import segment_commands
from omnical.calibration.procedures.tracks import (
    SlipPrior,
    body_arc_from_hedge,
    combine_estimates,
    move_arcs,
    procedure_tracks,
)
from omnical.errors import CalibrationError, ConfigError
from omnical.experiment.script import MotionScript, parse_script
from omnical.ips.beacons import BeaconMap, default_beacon_map
from omnical.kinematics.correction import CorrectionFactors
from omnical.kinematics.factors import Factor
from omnical.recording.recording import Recording
from omnical.robot.loader import load_robot
from omnical.twin.ips_params import IpsParams
from omnical.twin.params import TwinParams, default_twin
from omnical.twin.session import simulate_run

ROBOT = load_robot("rosy-mecanum")
TWIN = default_twin(ROBOT)
TRUTH = TWIN.true_factors
HEDGE = ROBOT.hedge_offset_m
SCALE_TOL = 0.005  # issue acceptance: each scaling within 0.5 %
CROSS_TOL = 1.5e-3  # and each cross-talk within 1.5 mrad/m
SCALES = ("scale_longitudinal", "scale_lateral", "scale_rotational")
CROSSTALKS = (
    "crosstalk_forward_rad_per_m",
    "crosstalk_reverse_rad_per_m",
    "crosstalk_left_rad_per_m",
    "crosstalk_right_rad_per_m",
)


@functools.cache
def scripts() -> tuple[MotionScript, MotionScript, MotionScript]:
    """The three default procedures, compiled for rosy-mecanum."""
    maps = (rotation_procedure(), longitudinal_procedure(), lateral_procedure())
    rot, lon, lat = (parse_script(m, ROBOT.limits) for m in maps)
    return rot, lon, lat


@functools.cache
def runs(seed: int, installed: CorrectionFactors | None = None) -> tuple[Recording, ...]:
    """Rotation, longitudinal and lateral runs on the default twin (cached per seed)."""
    params = TWIN if installed is None else TWIN.with_installed(installed)
    return tuple(
        simulate_run(s, ROBOT, params, seed=10 * seed + j) for j, s in enumerate(scripts())
    )


def relative_error(est: CorrectionFactors, name: str) -> float:
    return float(getattr(est, name) / getattr(TRUTH, name) - 1.0)


def absolute_error(est: CorrectionFactors, name: str) -> float:
    return float(getattr(est, name) - getattr(TRUTH, name))


def assert_within_acceptance(factors: CorrectionFactors, names: tuple[str, ...]) -> None:
    for name in names:
        if Factor(name).is_scale:
            assert abs(relative_error(factors, name)) <= SCALE_TOL, name
        else:
            assert abs(absolute_error(factors, name)) <= CROSS_TOL, name


# ------------------------------------------------------------------------------- scripts


def _moves(data: dict[str, Any]) -> list[dict[str, Any]]:
    return [s["move"] for s in data["steps"] if "move" in s]


def test_rotation_procedure_layout() -> None:
    data = rotation_procedure(turns=5, rate_radps=-0.8, distance_m=2.0, hold_s=3.5)
    script = parse_script(data, ROBOT.limits)
    kinds = [s.kind for s in script.steps]
    assert kinds == ["hold", "move"] * 4 + ["hold"]
    holds = [s.duration_s for s in script.steps if s.kind == "hold"]
    assert min(holds) == pytest.approx(3.5)
    approach, forward, turns, reverse = _moves(data)
    assert approach["vy_mps"] > 0.0
    assert forward["vx_mps"] == pytest.approx(0.3) and forward["distance_m"] == 2.0
    assert reverse["vx_mps"] == pytest.approx(-0.3) and reverse["distance_m"] == 2.0
    assert turns == {"wz_radps": -0.8, "angle_deg": 1800.0, "ramp": False, "marker": "turns-5"}
    turn_step = script.steps[5]
    assert turn_step.duration_s == pytest.approx(5 * 2 * math.pi / 0.8)  # the theoretical time


def test_translation_procedures_layout() -> None:
    lon = _moves(longitudinal_procedure(repeats=3, distance_m=3.0))
    assert [m["vx_mps"] for m in lon] == [0.25, -0.25] * 3
    assert all(m["distance_m"] == 3.0 for m in lon)
    plain = _moves(lateral_procedure(reference_m=0.0, repeats=2))
    assert [m["vy_mps"] for m in plain] == [0.25, -0.25] * 2
    framed = _moves(lateral_procedure(repeats=2))
    directions = [
        ("vx" if "vx_mps" in m else "vy", math.copysign(1, m.get("vx_mps", m.get("vy_mps", 0))))
        for m in framed
    ]
    loop = [("vx", 1.0), ("vy", 1.0), ("vx", -1.0), ("vy", -1.0)]
    assert directions == [("vx", 1.0), ("vx", -1.0), *loop, *loop, ("vx", 1.0)]


@pytest.mark.parametrize("which", ["rotation", "longitudinal", "lateral"])
def test_default_procedures_stay_inside_the_beacon_map(which: str) -> None:
    script = dict(zip(("rotation", "longitudinal", "lateral"), scripts(), strict=True))[which]
    beacons = default_beacon_map()
    commanded = nominal_path(script, TWIN.start_pose_map)
    real = nominal_path(script, TWIN.start_pose_map, true_factors=TRUTH)
    assert hull_margin_m(commanded, beacons) >= 0.35
    assert hull_margin_m(real, beacons) >= 0.35
    assert 60.0 <= script.duration_s <= 210.0


@pytest.mark.parametrize(
    ("function", "changes"),
    [
        (rotation_procedure, {"hold_s": 2.0}),
        (rotation_procedure, {"turns": 0}),
        (rotation_procedure, {"rate_radps": 0.0}),
        (rotation_procedure, {"distance_m": -1.0}),
        (rotation_procedure, {"approach_left_m": -0.5}),
        (longitudinal_procedure, {"repeats": 0}),
        (longitudinal_procedure, {"speed_mps": math.nan}),
        (lateral_procedure, {"reference_m": -1.0}),
        (lateral_procedure, {"repeats": True}),
    ],
)
def test_procedure_parameters_are_checked(function: Any, changes: dict[str, Any]) -> None:
    with pytest.raises(ConfigError, match="procedure parameter"):
        function(**changes)


def test_procedure_beyond_the_speed_limits_is_refused() -> None:
    from omnical.errors import LimitError

    with pytest.raises(LimitError):
        parse_script(rotation_procedure(rate_radps=3.0), ROBOT.limits)


def test_nominal_path_dead_reckons_the_true_factors() -> None:
    data = {"steps": [{"move": {"vx_mps": 0.2, "distance_m": 2.0}}, {"hold": {"duration_s": 1}}]}
    script = parse_script(data, ROBOT.limits)
    commanded = nominal_path(script, (1.0, 2.0, 0.5), step_s=0.002)
    assert commanded[-1] == pytest.approx(
        [1.0 + 2.0 * math.cos(0.5), 2.0 + 2.0 * math.sin(0.5), 0.5], abs=1e-3
    )
    truth = CorrectionFactors(scale_longitudinal=1.02, crosstalk_forward_rad_per_m=0.05)
    real = nominal_path(script, (0.0, 0.0, 0.0), true_factors=truth, step_s=0.002)
    length = 2.0 / 1.02
    assert real[-1, 2] == pytest.approx(0.05 * length, rel=1e-3)
    chord = length * np.sinc(0.05 * length / (2 * np.pi))
    assert float(np.hypot(*real[-1, :2])) == pytest.approx(chord, abs=1e-3)
    with pytest.raises(ConfigError, match="start_pose_map"):
        nominal_path(script, (0.0, 0.0))


def test_hull_margin() -> None:
    square = BeaconMap(
        np.array([1, 2, 3, 4]), np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [4, 4, 0.0]])
    )
    assert hull_margin_m([[2.0, 2.0]], square) == pytest.approx(2.0)
    assert hull_margin_m([[2.0, 2.0], [1.0, 3.5]], square) == pytest.approx(0.5)
    assert hull_margin_m([[-1.0, 2.0]], square) == pytest.approx(-1.0)
    line = BeaconMap(np.array([1, 2, 3]), np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]))
    with pytest.raises(ConfigError, match="one line"):
        hull_margin_m([[0.0, 0.0]], line)


# ------------------------------------------------------------------------------- helpers


def test_combine_estimates_weights_and_inflates() -> None:
    agree = combine_estimates([1.0, 2.0, 4.0], [1.0, 1.0, 2.0])
    assert agree.value == pytest.approx((1 + 2 + 4 / 4) / 2.25)
    assert agree.sigma == pytest.approx(1 / math.sqrt(2.25))  # χ²/dof < 1: not shrunk
    assert agree.n == 3
    disagree = combine_estimates([0.0, 10.0], [1.0, 1.0])
    assert disagree.sigma == pytest.approx(math.sqrt(0.5) * math.sqrt(50.0))  # Birge ratio
    assert combine_estimates([3.0, 99.0], [0.5, math.inf]).value == 3.0
    assert math.isinf(combine_estimates([3.0], [math.inf]).sigma)
    with pytest.raises(CalibrationError):
        combine_estimates([], [])
    with pytest.raises(CalibrationError):
        combine_estimates([1.0], [0.0])


def test_slip_prior() -> None:
    slip = SlipPrior()
    assert slip.relative_sigma(18.85) == pytest.approx(0.003 * math.sqrt(1.0 / 18.85))
    assert slip.relative_sigma(0.1) == 0.003  # shorter than the correlation: no averaging
    assert slip.heading_sigma_rad(3.5, 14.0) == pytest.approx(3e-4 * 3.5 * math.sqrt(1 / 14))
    assert SlipPrior(0.0, 0.0).heading_sigma_rad(3.0, 10.0) == 0.0
    with pytest.raises(CalibrationError):
        SlipPrior(fraction=-0.1)
    with pytest.raises(CalibrationError):
        SlipPrior(correlation_s=0.0)


@pytest.mark.parametrize("direction", [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)])
@pytest.mark.parametrize("kappa", [0.0389, -0.0277, 0.0])
@pytest.mark.parametrize("offset", [(0.04, -0.03), (0.15, 0.10)])
def test_hedge_arc_of_a_rigid_body(
    direction: tuple[float, float], kappa: float, offset: tuple[float, float]
) -> None:
    """Drive a rigid body along an arc; the hedgehog's arc converts back to the centre's."""
    u, o = np.array(direction), np.array(offset)
    theta0 = 0.3

    def rotate(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
        c, s_ = np.cos(theta), np.sin(theta)
        return np.stack([c * v[0] - s_ * v[1], s_ * v[0] + c * v[1]], axis=-1)

    def hedge_at(s: np.ndarray) -> np.ndarray:
        theta = theta0 + kappa * s
        if kappa == 0.0:
            centre = s[:, None] * rotate(np.full_like(s, theta0), u)
        else:  # ∫ R(θ0 + κσ) u dσ = (R(θ) − R(θ0)) J⁻¹ u / κ
            ju_inv = np.array([u[1], -u[0]])
            centre = (rotate(theta, ju_inv) - rotate(np.full_like(s, theta0), ju_inv)) / kappa
        return np.asarray(centre + rotate(theta, o), dtype=np.float64)

    s = np.linspace(0.0, 3.0, 400)
    hedge = hedge_at(s)
    fit = fit_circle(hedge)
    k, ratio, delta = body_arc_from_hedge(fit.curvature_per_m, u, o)
    assert k == pytest.approx(kappa, abs=1e-9)
    assert arc_length(fit, hedge[0], hedge[-1]) == pytest.approx(3.0 * ratio, rel=1e-7)
    h = 1e-6
    step = (hedge_at(np.array([h])) - hedge_at(np.array([-h])))[0]
    travel = rotate(np.array([theta0]), u)[0]
    expected = math.remainder(
        math.atan2(step[1], step[0]) - math.atan2(travel[1], travel[0]), 2 * math.pi
    )
    assert delta == pytest.approx(expected, abs=1e-8)


# ------------------------------------------------------------------------------- on the twin


def test_rotation_procedure_segments_from_cmd_vel() -> None:
    rec = runs(1)[0]
    cmd = rec.topic("/cmd_vel")
    segments = segment_commands(cmd.t_s(), cmd["vx_mps"], cmd["vy_mps"], cmd["wz_radps"])
    kinds = [s.kind for s in segments]
    assert kinds == [
        "still",
        "left",
        "still",
        "forward",
        "still",
        "rotate_ccw",
        "still",
        "reverse",
        "still",
    ]
    assert segments[5].commanded_integral[2] == pytest.approx(6 * math.pi, abs=0.02)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_procedures_recover_table2(seed: int) -> None:
    """Issue acceptance: every scaling within 0.5 %, every cross-talk within 1.5 mrad/m."""
    est = analyse_procedures(runs(seed), hedge_offset_m=HEDGE)
    assert est.measured == tuple(est.sigma)  # all seven
    assert est.notes == ()
    assert_within_acceptance(est.factors, SCALES + CROSSTALKS)
    for name in SCALES + CROSSTALKS:  # the uncertainties are honest
        error = getattr(est.factors, name) - getattr(TRUTH, name)
        assert abs(error) <= 4.5 * est.sigma[name], name
        assert est.sigma[name] < (0.002 if Factor(name).is_scale else 5e-4), name
    assert est.residual == est.factors  # nothing installed: the totals are the residuals


def test_rotation_analysis_alone() -> None:
    result = analyse_procedures(runs(1)[0], hedge_offset_m=HEDGE).rotation
    assert result is not None
    (turn,) = result.measurements
    assert turn.commanded_angle_rad == pytest.approx(6 * math.pi, abs=0.02)
    assert turn.odom_angle_rad == pytest.approx(turn.commanded_angle_rad, rel=2e-3)
    # seed 000 §3.2.1: "the initial deviation for three complete rotations was about 25.5°"
    assert math.degrees(turn.odom_angle_rad - turn.real_angle_rad) == pytest.approx(25.0, abs=1.0)
    assert abs(result.estimate.value / TRUTH.scale_rotational - 1.0) <= SCALE_TOL
    assert result.estimate.sigma == pytest.approx(turn.scale_std)
    assert result.factors.scale_rotational == result.estimate.value


def test_longitudinal_analysis_alone() -> None:
    result = analyse_procedures(runs(2)[1], hedge_offset_m=HEDGE).translation
    assert [s.kind for s in result.segments] == ["forward", "reverse"] * 2
    assert set(result.estimates) == {
        "scale_longitudinal",
        "crosstalk_forward_rad_per_m",
        "crosstalk_reverse_rad_per_m",
    }
    assert abs(relative_error(result.factors, "scale_longitudinal")) <= SCALE_TOL
    for seg in result.segments:  # each move alone: scaling from two stand-still averages
        assert abs(seg.scale / TRUTH.scale_longitudinal - 1.0) <= 4.0 * seg.scale_std
    # back and forth, the chords measure the sum of the two cross-talks; each one alone
    # comes from the arcs' curvature, about 0.8 mrad/m here
    total = sum(absolute_error(result.factors, n) for n in CROSSTALKS[:2])
    assert abs(total) <= CROSS_TOL
    for name in CROSSTALKS[:2]:
        assert abs(absolute_error(result.factors, name)) <= 4.0 * result.estimates[name].sigma


def test_lateral_analysis_alone_measures_all_crosstalks() -> None:
    result = analyse_procedures(runs(3)[2], hedge_offset_m=HEDGE).translation
    assert set(result.estimates) == set(SCALES[:2] + CROSSTALKS)
    assert_within_acceptance(result.factors, SCALES[:2] + CROSSTALKS)


def test_heading_chains_beat_single_arcs() -> None:
    """Seed 000's per-arc curvature is unbiased but ≈ 2 mrad/m per lateral move."""
    chain = analyse_procedures(runs(1)[2], hedge_offset_m=HEDGE, method="chain").translation
    arcs = analyse_procedures(runs(1)[2], hedge_offset_m=HEDGE, method="arcs").translation
    for name in CROSSTALKS[2:]:
        assert arcs.estimates[name].sigma >= 3.0 * chain.estimates[name].sigma
        assert abs(absolute_error(arcs.factors, name)) <= 4.0 * arcs.estimates[name].sigma
    lateral = [s for s in arcs.segments if s.kind in ("left", "right")]
    assert len(lateral) == 4
    for seg in lateral:
        truth = getattr(TRUTH, f"crosstalk_{seg.kind}_rad_per_m")
        assert abs(seg.crosstalk_arc_rad_per_m - truth) <= 4.0 * seg.crosstalk_arc_std_rad_per_m
        assert 1.2e-3 < seg.crosstalk_arc_std_rad_per_m < 5e-3
    for name in SCALES[:2]:  # the scalings do not depend on the method
        assert arcs.estimates[name] == chain.estimates[name]


def test_odometry_straightens_the_start_jogs_of_friction() -> None:
    """Friction makes every move start with a jog that the arcs take out with the odometry.

    At a stand-still each wheel's PI loop keeps the drive that just fails to break the wheel
    loose; into the next move the wheels that keep their direction start at once, the others
    once their integrator has unwound, so a lateral move after a longitudinal one starts with
    a diagonal jog of ≈ 6 mm (and a reverse move after a lateral one, a lateral jog). With a
    noiseless IPS and no slip the raw arcs miss the headings at the stand-stills by up to
    ≈ 6 mrad (reverse cross-talk off by ≈ −0.8 mrad/m, right by ≈ −0.7 mrad/m over the three
    procedures); straightened by the odometry, by a few tenths of a mrad.
    """
    params = replace(TWIN, ips=IpsParams.ideal(), slip_sigma=0.0)
    rec = simulate_run(scripts()[2], ROBOT, params, seed=7)
    tracks = procedure_tracks(rec)
    gt = rec.topic("/ground_truth")
    gt_t = gt.t_s(tracks.t0_ns)
    gt_yaw = np.unwrap(np.asarray(gt["yaw_rad"], dtype=np.float64))

    def worst_heading_error(straighten: bool) -> float:
        arcs, notes = move_arcs(tracks, hedge_offset_xy_m=HEDGE[:2], straighten=straighten)
        assert len(arcs) == 11 and notes == []
        worst = 0.0
        for arc in arcs:
            for heading, still in (
                (arc.body_heading_at("start")[0], arc.before),
                (arc.body_heading_at("end")[0], arc.after),
            ):
                inside = (gt_t >= still.t_start_s) & (gt_t <= still.t_end_s)
                error = heading - float(gt_yaw[inside].mean())
                worst = max(worst, abs(math.remainder(error, 2.0 * math.pi)))
        return worst

    assert worst_heading_error(straighten=False) > 4e-3
    assert worst_heading_error(straighten=True) < 6e-4
    result = analyse_procedures(rec, hedge_offset_m=HEDGE).translation
    for name in CROSSTALKS:
        assert abs(absolute_error(result.factors, name)) < 3e-4, name


def test_compensated_robot_gives_identity_residuals() -> None:
    est = analyse_procedures(runs(4, TRUTH), TRUTH, hedge_offset_m=HEDGE)
    residual = est.residual
    for name in SCALES:
        assert getattr(residual, name) == pytest.approx(1.0, abs=SCALE_TOL)
    for name in CROSSTALKS:
        assert getattr(residual, name) == pytest.approx(0.0, abs=CROSS_TOL)
    assert_within_acceptance(est.factors, SCALES + CROSSTALKS)
    assert TRUTH.composed_with(residual).as_vector() == pytest.approx(est.factors.as_vector())
    assert est.rotation is not None
    (turn,) = est.rotation.measurements
    assert abs(math.degrees(turn.odom_angle_rad - turn.real_angle_rad)) < 3.0  # paper: < 3°


def test_partly_compensated_robot_composes_to_the_truth() -> None:
    """A first iteration's factors installed: the residuals compose to the truth again."""
    first = CorrectionFactors(1.0, 1.1, 1.01, 0.0, 0.0, 0.03, -0.02)
    est = analyse_procedures(runs(5, first), first, hedge_offset_m=HEDGE)
    assert est.installed == first
    assert_within_acceptance(est.factors, SCALES + CROSSTALKS)
    assert est.residual.scale_lateral == pytest.approx(1.13 / 1.1, abs=SCALE_TOL)
    assert est.residual.crosstalk_left_rad_per_m == pytest.approx(0.0389 - 0.03, abs=CROSS_TOL)


def test_analysis_never_reads_ground_truth_or_markers() -> None:
    full = runs(1)
    stripped = [r.without("/ground_truth", "/omnical/events") for r in full]
    assert not any(r.has("/ground_truth") or r.has("/omnical/events") for r in stripped)
    a = analyse_procedures(full, hedge_offset_m=HEDGE)
    b = analyse_procedures(stripped, hedge_offset_m=HEDGE)
    assert b.factors == a.factors
    assert b.sigma == a.sigma


def test_hedge_offset_is_corrected() -> None:
    """Noiseless twin, hedgehog 18 cm off centre: exact with the offset, biased without."""
    params = TwinParams.ideal_twin(true_factors=TRUTH, hedge_offset_m=(0.15, 0.10, 0.4))
    rot, _, _ = scripts()
    lat = parse_script(lateral_procedure(repeats=1), ROBOT.limits)
    recs = [simulate_run(s, ROBOT, params, seed=7) for s in (rot, lat)]
    exact = analyse_procedures(recs, hedge_offset_m=(0.15, 0.10, 0.4))
    for name in SCALES:
        assert abs(relative_error(exact.factors, name)) < 5e-5, name
    for name in CROSSTALKS:
        assert abs(absolute_error(exact.factors, name)) < 2e-5, name
    naive = analyse_procedures(recs)  # hedgehog assumed at the centre
    assert relative_error(naive.factors, "scale_lateral") < -0.004


def test_missing_data_is_reported() -> None:
    rotation_run, longitudinal_run, _ = runs(1)
    no_turn = analyse_procedures(longitudinal_run)
    assert no_turn.rotation is None
    assert no_turn.held["scale_rotational"] == "not observable: no turn was analysed"
    with pytest.raises(CalibrationError, match="/odom"):
        analyse_procedures(longitudinal_run.without("/odom"))
    with pytest.raises(CalibrationError, match="beacon_raw_distance"):
        analyse_procedures([rotation_run.without("/beacon_raw_distance")])
    hold = parse_script({"steps": [{"hold": {"duration_s": 5}}]}, ROBOT.limits)
    with pytest.raises(CalibrationError, match="no translation"):
        analyse_procedures(simulate_run(hold, ROBOT, TWIN, seed=1))
    with pytest.raises(CalibrationError, match="no recordings"):
        analyse_procedures([])
    with pytest.raises(CalibrationError, match="hedge_offset_m"):
        analyse_procedures(rotation_run, hedge_offset_m=(0.1,))


def test_rotation_run_alone_measures_what_it_moves() -> None:
    est: ProcedureEstimate = analyse_procedures(runs(1)[0], hedge_offset_m=HEDGE)
    with pytest.raises(AttributeError):
        est.factors = CorrectionFactors()  # type: ignore[misc]
    # the approach (left), forward and reverse moves are translations between stand-stills;
    # the 1 m approach measures the lateral scaling, but not the left cross-talk to 10 mrad/m
    assert est.measured == SCALES + CROSSTALKS[:2]
    assert est.factors.crosstalk_right_rad_per_m == est.installed.crosstalk_right_rad_per_m
    assert math.isinf(est.sigma["crosstalk_right_rad_per_m"])
    # not measured, or measured too loosely: held at the installed value, with the reason
    assert set(est.held) == {"crosstalk_left_rad_per_m", "crosstalk_right_rad_per_m"}
    assert est.held["crosstalk_right_rad_per_m"] == "not observable: no right move was analysed"
    assert "exceeds 0.01" in est.held["crosstalk_left_rad_per_m"]
    assert est.factors.crosstalk_left_rad_per_m == est.installed.crosstalk_left_rad_per_m
    assert math.isinf(est.sigma["crosstalk_left_rad_per_m"])
    assert any(n.startswith("crosstalk_left_rad_per_m: not observable") for n in est.notes)
    assert abs(relative_error(est.factors, "scale_rotational")) <= SCALE_TOL

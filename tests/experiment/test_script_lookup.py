"""Script lookups by bisection: right at every step boundary of a 100,000-step script, and the
Runner's batched and per-tick paths send the same commands."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.experiment.ports import BatchClock, Clock
from omnical.experiment.runner import run_script
from omnical.experiment.script import (
    MotionScript,
    ScheduledCommandSource,
    Step,
    TwistSequence,
    parse_script,
)
from omnical.robot.loader import load_robot
from omnical.twin.clock import TwinClock
from omnical.twin.params import TwinParams
from omnical.twin.simulator import DigitalTwin

ROSY = load_robot("rosy-mecanum")
N_STEPS = 100_000


def _long_script() -> MotionScript:
    """Steps of every kind back to back: holds, ramped moves, short triangles, step commands."""
    rng = np.random.default_rng(5)
    steps = []
    t = 0.0
    for i in range(N_STEPS):
        kind = i % 4
        if kind == 0:
            step = Step(i, "hold", (0.0, 0.0, 0.0), t, 0.0, 0.0, float(rng.uniform(0.1, 2)), None)
        else:
            twist = (float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.5, 0.5)), 0.3)
            rise = 0.0 if kind == 3 else float(rng.uniform(0.05, 0.5))
            peak = 1.0 if kind != 2 else float(rng.uniform(0.2, 0.9))
            cruise = 0.0 if kind == 2 else float(rng.uniform(0.0, 3.0))
            step = Step(i, "move", twist, t, rise, peak, cruise, f"m{i}")
        steps.append(step)
        t = step.end_s
    return MotionScript("long", 50.0, tuple(steps))


def test_lookup_is_right_at_every_boundary_of_100000_steps() -> None:
    script = _long_script()
    steps = script.steps
    starts = np.array([s.start_s for s in steps])
    before = np.nextafter(starts, -np.inf)
    end = script.duration_s
    # scalar lookups: a boundary belongs to the step it starts, the instant before to the one before
    for i in range(0, N_STEPS, 7):
        t = float(starts[i])
        assert script.step_at(t) is steps[i]
        f = steps[i].fraction_at(t)
        assert script.twist_at(t) == tuple(v * f for v in steps[i].twist)
        if i > 0:
            assert script.step_at(float(before[i])) is steps[i - 1]
    assert script.step_at(float(np.nextafter(0.0, -1.0))) is None
    assert script.step_at(end) is None
    assert script.twist_at(end) == (0.0, 0.0, 0.0)
    # vectorised lookups: every boundary, the instant before, and the middle of every step
    mids = starts + 0.5 * np.array([s.duration_s for s in steps])
    t_all = np.concatenate([starts, before, mids, [end, end + 1.0, -1.0]])
    expected_index = np.concatenate(
        [np.arange(N_STEPS), np.arange(-1, N_STEPS - 1), np.arange(N_STEPS), [-1, -1, -1]]
    )
    np.testing.assert_array_equal(script.step_index_at(t_all), expected_index)
    twists = script.twists_at(t_all)
    sample = np.arange(0, len(t_all), 13)
    scalar = np.array([script.twist_at(float(t_all[k])) for k in sample])
    np.testing.assert_array_equal(twists[sample], scalar)  # bit for bit


def test_steps_out_of_order_keep_first_match_semantics() -> None:
    a = Step(0, "move", (0.2, 0.0, 0.0), 2.0, 0.0, 1.0, 1.0, None)
    b = Step(1, "move", (0.0, 0.1, 0.0), 0.0, 0.0, 1.0, 2.5, None)  # overlaps a
    script = MotionScript("odd", 50.0, (a, b))
    assert script.step_at(2.2) is a
    assert script.step_at(1.0) is b
    assert script.step_at(2.6) is a
    np.testing.assert_array_equal(script.step_index_at([2.2, 1.0, 3.5]), [0, 1, -1])
    np.testing.assert_array_equal(script.twists_at([2.2, 1.0]), [[0.2, 0.0, 0.0], [0.0, 0.1, 0.0]])


def test_twist_sequence_vectorised_lookup_matches_scalar() -> None:
    t = np.arange(0.0, 5.0, 0.1)
    seq = TwistSequence.from_arrays("s", t, np.column_stack([np.sin(t), np.cos(t), t]), 50.0)
    assert isinstance(seq, ScheduledCommandSource)
    q = np.concatenate([t, np.nextafter(t, -np.inf), [-0.1, seq.duration_s, 4.99]])
    np.testing.assert_array_equal(seq.twists_at(q), [seq.twist_at(float(x)) for x in q])
    np.testing.assert_array_equal(
        seq.step_index_at(q), [0 if seq.step_at(float(x)) else -1 for x in q]
    )


class _TickClock:
    """A clock that is not a BatchClock: the Runner goes tick by tick."""

    def __init__(self, twin: DigitalTwin) -> None:
        self._twin = twin

    def now_s(self) -> float:
        return self._twin.t_s

    def sleep_until(self, t_s: float) -> None:
        self._twin.advance_to(t_s)


@pytest.mark.parametrize("engine", ["compiled", "python"])
def test_runner_batched_and_per_tick_paths_agree(engine: str) -> None:
    script = parse_script(
        {
            "rate_hz": 40,
            "steps": [
                {"hold": {"duration_s": 0.5, "marker": "a"}},
                {"move": {"vx_mps": 0.3, "distance_m": 0.6}},
                {"move": {"vy_mps": -0.2, "wz_radps": 0.4, "duration_s": 1.3, "ramp": False}},
            ],
        },
        ROSY.limits,
    )
    logs = []
    twins = []
    for make_clock in (TwinClock, _TickClock):
        twin = DigitalTwin(ROSY, TwinParams.ideal_twin(), seed=1, engine=engine)  # type: ignore[arg-type]
        clock: Clock = make_clock(twin)
        assert isinstance(clock, BatchClock) == (make_clock is TwinClock)
        ticks: list[float] = []
        heard: list[tuple[float, str]] = []
        logs.append(run_script(script, twin, clock, on_tick=lambda t, _, ts=ticks: ts.append(t),
                               on_event=lambda t, text, h=heard: h.append((t, text))))  # fmt: skip
        assert ticks[-1] == pytest.approx(script.duration_s, abs=1 / 40)
        # a real-time clock's markers as they happen (a live view); a batch is computed
        assert tuple(heard) == (() if make_clock is TwinClock else logs[-1].events)
        twins.append(twin)
    batched, per_tick = logs
    np.testing.assert_array_equal(batched.cmd_vel, per_tick.cmd_vel)
    assert batched.events == per_tick.events
    assert len(batched.events) == 6
    np.testing.assert_array_equal(twins[0].log().ground_truth, twins[1].log().ground_truth)
    np.testing.assert_array_equal(twins[0].log().odom, twins[1].log().odom)

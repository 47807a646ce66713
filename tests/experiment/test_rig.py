"""``run_script_on``: one experiment for every rig (the twin's here; the serial rig's in
``tests/cli/test_run_cli.py``, against the same script on the twin)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from omnical.experiment.rig import LEAD_IN_S, TAIL_S, run_script_on
from omnical.experiment.script import parse_script
from omnical.recording.recording import RecordingBuilder
from omnical.robot.loader import load_robot
from omnical.twin.params import default_twin
from omnical.twin.rig import TwinRig
from omnical.twin.session import simulate_run

ROBOT = load_robot("rosy-mecanum")
SCRIPT = parse_script(
    {"name": "two", "steps": [{"move": {"vx_mps": 0.2, "distance_m": 0.6}}, {"hold": {"duration_s": 0.5}}]},
    ROBOT.limits,
)  # fmt: skip


def test_a_script_on_the_twin_rig_is_what_simulate_records() -> None:
    params = default_twin(ROBOT)
    builder = RecordingBuilder()
    log = run_script_on(TwinRig(ROBOT, params, seed=3), SCRIPT, builder)
    rec = builder.build()
    same = simulate_run(SCRIPT, ROBOT, params, seed=3)
    assert rec.topics == same.topics
    for topic in rec.topics:
        np.testing.assert_array_equal(rec.topic(topic).t_ns, same.topic(topic).t_ns)
    # the lead-in and the tail stand still around the script's commands
    t_cmd = log.cmd_vel[:, 0]
    assert t_cmd[0] == pytest.approx(LEAD_IN_S)
    odom = (np.asarray(rec.topic("/odom").t_ns) - rec.topic("/odom").t_ns[0]) / 1e9
    assert odom[-1] == pytest.approx(t_cmd[-1] + TAIL_S, abs=0.03)


def test_installed_factors_compensate_and_are_recorded() -> None:
    params = default_twin(ROBOT)
    installed = params.true_factors  # the truth installed: the twin drives as commanded
    runs = {}
    for name, factors in (("none", None), ("truth", installed)):
        builder = RecordingBuilder()
        run_script_on(
            TwinRig(ROBOT, params, seed=1), SCRIPT, builder, installed=factors,
            record_installed=True,
        )  # fmt: skip
        runs[name] = builder.build()
    events = [json.loads(str(e)) for e in runs["truth"].topic("/omnical/events")["text"]]
    assert events[0] == {"omnical": "installed_factors", "factors": installed.as_dict()}
    assert all(e.get("omnical") != "installed_factors" for e in (
        json.loads(str(t)) for t in runs["none"].topic("/omnical/events")["text"]
    ))  # fmt: skip

    def travelled(name: str) -> float:
        g = runs[name].topic("/ground_truth")
        return float(np.hypot(g["x_m"][-1] - g["x_m"][0], g["y_m"][-1] - g["y_m"][0]))

    # installed, the longitudinal scale (1.02) is compensated: the truth travels 2 % further
    # (the rest of the shortfall is the twin's radius errors, slip and start-up)
    scale = params.true_factors.scale_longitudinal
    assert travelled("truth") / travelled("none") == pytest.approx(scale, abs=0.003)


def test_a_stop_in_the_tail_keeps_the_commands_and_the_events() -> None:
    """A Ctrl-C while the robot stands after the script (or before it) ends the run with what
    was recorded: the review found the tail's stop lost /cmd_vel and the events."""
    from contextlib import contextmanager

    base = TwinRig(ROBOT, default_twin(ROBOT), seed=2)

    class StoppedAtRest:
        def __init__(self, after_holds: int) -> None:
            self.after = after_holds

        @contextmanager
        def session(self, sink, **kw):  # type: ignore[no-untyped-def]
            with base.session(sink, **kw) as run:
                hold, left = run.hold, [self.after]

                def stopping_hold(duration_s: float) -> None:
                    if left[0] == 0:
                        raise KeyboardInterrupt
                    left[0] -= 1
                    hold(duration_s)

                run.hold = stopping_hold  # type: ignore[method-assign]
                yield run

    builder = RecordingBuilder()  # stopped in the tail
    log = run_script_on(StoppedAtRest(1), SCRIPT, builder)  # type: ignore[arg-type]
    rec = builder.build()
    assert log.interrupted and isinstance(log.interruption, KeyboardInterrupt)
    assert rec.has("/odom") and rec.has("/cmd_vel") and rec.has("/omnical/events")
    builder = RecordingBuilder()  # stopped before the twin ran: nothing sensed, no error
    log = run_script_on(StoppedAtRest(0), SCRIPT, builder)  # type: ignore[arg-type]
    assert log.interrupted and len(log.cmd_vel) == 0 and not builder.build().has("/odom")

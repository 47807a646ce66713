"""The seed 003 estimator offline on a bag written by ``omnical run``: the loop's own trajectory.

``omnical run seed003-triangle --model omni-x`` closes the loop on the seed 003 estimate and
writes RUN.mcap. Read back, the bag's /dead_wheels, /imu and /imu/mag give, through the same
estimator offline, the trajectory that closed the loop (recomputed in-process with the same seed),
and the pose at which the controller stopped (within its 1 cm goal tolerance of the last goal).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from omnical.bags.bag import read_bag
from omnical.cli.main import app
from omnical.estimation.se2 import between_poses
from omnical.estimation.seed003_estimator import seed003_samples_of, seed003_track
from omnical.experiment.library import builtin_task
from omnical.robot.loader import load_robot
from omnical.services.seed003 import run_seed003_test
from omnical.twin.params import load_twin

OMNI = load_robot("omni-x")
SEED = 3


@pytest.fixture(scope="module")
def triangle_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("run") / "triangle.mcap"
    result = CliRunner().invoke(
        app,
        ["run", "seed003-triangle", "--model", "omni-x", "--seed", str(SEED), "--out", str(out)],
    )
    assert result.exit_code == 0, result.output
    assert "closed on the seed 003 estimate" in result.output
    return out


def _loop_start_s(bag: object) -> float:
    """Seconds from the bag's first message to the controller's 'start' event."""
    events = bag.topic("/omnical/events")  # type: ignore[attr-defined]
    t_s = events.t_s(bag.start_ns)  # type: ignore[attr-defined]
    starts = [
        float(t)
        for t, text in zip(t_s, events["text"], strict=True)
        if json.loads(text).get("event") == "start"
    ]
    assert len(starts) == 1
    return starts[0]


def test_offline_estimate_from_the_run_bag_is_the_loops_trajectory(triangle_bag: Path) -> None:
    bag = read_bag(triangle_bag)
    start_s = _loop_start_s(bag)
    offline = seed003_track(
        seed003_samples_of(bag, OMNI.dead_wheels, since_s=start_s - 1e-6), OMNI.dead_wheels
    )
    # the same run in-process (same preset, twin and seed): its in-loop estimate
    task = builtin_task("seed003-triangle")
    assert task is not None
    test = run_seed003_test(task, OMNI, load_twin("default", OMNI), seed=SEED)
    assert test.run.estimates is not None
    in_loop = between_poses(np.asarray(test.run.path_origin_map), test.run.estimates[:, 1:])
    # it is the same run: the bag's ground truth is the in-process one
    truth = bag.topic("/ground_truth")
    np.testing.assert_allclose(
        np.asarray(truth["x_m"]), test.run.twin_log.ground_truth_pose[:, 0], atol=1e-9
    )
    assert len(in_loop) > 500
    np.testing.assert_allclose(offline[: len(in_loop), 1:], in_loop, atol=1e-9)
    # the loop stopped when its estimate was within 1 cm of the last goal (the start point);
    # the bag's offline estimate says so too, at the loop's last tick
    cmd = bag.topic("/cmd_vel")
    t_end = float(cmd.t_s(bag.start_ns)[-1])
    at_end = offline[np.searchsorted(offline[:, 0], t_end, side="right") - 1]
    assert np.hypot(at_end[1], at_end[2]) < 0.01
    # and the robot moved: the triangle's far corner is 1.2 m away
    assert offline[:, 1].max() > 1.15


def test_run_bag_has_the_seed003_topics(triangle_bag: Path) -> None:
    bag = read_bag(triangle_bag)
    for topic in ("/dead_wheels", "/imu", "/imu/mag", "/odom", "/ground_truth", "/cmd_vel"):
        assert bag.has(topic), topic

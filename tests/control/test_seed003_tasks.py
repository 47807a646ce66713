"""Seed 003's tests as built-in controller tasks, and the paper's path-deviation measure."""

from __future__ import annotations

import numpy as np
import pytest

from omnical.control.centred import CentredMode, task_controller
from omnical.errors import ConfigError
from omnical.experiment.library import (
    BUILTIN_TASKS,
    BuiltinTask,
    builtin_script_names,
    builtin_task,
    builtin_task_names,
)
from omnical.paper import SEED003_PAPER_TEST_ERRORS
from omnical.services.seed003 import max_leg_deviation


def test_tasks_carry_the_papers_coordinates() -> None:
    assert builtin_task_names() == [
        "seed003-centred-turning",
        "seed003-driving-forward",
        "seed003-square",
        "seed003-triangle",
    ]
    assert not set(builtin_task_names()) & set(builtin_script_names())
    assert {t.slug for t in BUILTIN_TASKS} == set(SEED003_PAPER_TEST_ERRORS)
    cm = {t.slug: np.array(t.reference_m) * 100 for t in BUILTIN_TASKS}
    # seed 003 §IV.B: X = {0, 120, 120, 0, 0}, Y = {0, 0, −120, −120, 0}; X = {0, 120, 60, 0},
    # Y = {0, 0, 60, 0} (cm)
    np.testing.assert_allclose(cm["square"][:, 0], [0, 120, 120, 0, 0])
    np.testing.assert_allclose(cm["square"][:, 1], [0, 0, -120, -120, 0])
    np.testing.assert_allclose(cm["triangle"][:, 0], [0, 120, 60, 0])
    np.testing.assert_allclose(cm["triangle"][:, 1], [0, 0, 60, 0])
    np.testing.assert_allclose(cm["centred-turning"][-1], [100, 100])
    np.testing.assert_allclose(cm["driving-forward"][-1], [125, 100])
    assert builtin_task("tour") is None


def test_task_controller_modes_and_goals() -> None:
    modes = {t.slug: task_controller(t).mode for t in BUILTIN_TASKS}
    assert modes == {
        "centred-turning": CentredMode.CENTRED_TURNING,
        "driving-forward": CentredMode.DRIVING_FORWARD,
        "square": CentredMode.TRANSLATE,
        "triangle": CentredMode.TRANSLATE,
    }
    square = builtin_task("seed003-square")
    assert square is not None
    assert task_controller(square).goals_m == square.reference_m[1:]
    bad = BuiltinTask("x", "x", "x", "spiral", ((1.0, 0.0),), ((0.0, 0.0), (1.0, 0.0)))
    with pytest.raises(ConfigError, match="unknown mode 'spiral'"):
        task_controller(bad)


def test_deviation_is_from_the_leg_being_driven() -> None:
    square = np.array([(0.0, 0.0), (1.2, 0.0), (1.2, -1.2), (0.0, -1.2), (0.0, 0.0)])
    # the third leg (to (0, −1.2)) driven 16 cm short of the line, and 4 cm inside on the second
    path = np.array([(1.16, -0.6), (0.5, -1.04), (0.1, -1.04)])
    legs = np.array([1, 2, 2])
    err = max_leg_deviation(path, square, legs)
    assert err.first == pytest.approx(4.0) and err.second == pytest.approx(16.0)
    # the nearest segment instead would put (0.1, −1.04) on the fourth leg: a 10 cm "x error"
    assert max_leg_deviation(path, square, np.array([1, 2, 3])).first == pytest.approx(10.0)

"""The topic names a command's options default to are the canonical ones of recording.topics.

The CLI imports no library at start-up, so such a default is written out in the command's
signature; this holds it to the constant.
"""

from __future__ import annotations

import inspect

from omnical.cli.calibrate_estimate import estimate
from omnical.cli.evaluate import evaluate
from omnical.recording.topics import DEAD_WHEELS


def test_the_dead_wheel_topic_defaults_to_the_canonical_one() -> None:
    for command in (evaluate, estimate):
        default = inspect.signature(command).parameters["dead_wheel_topic"].default
        assert default == DEAD_WHEELS, command.__name__

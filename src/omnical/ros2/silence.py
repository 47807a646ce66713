"""Said once when a ROS 2 command's input stays silent: the topic or port, the domain and, for
a topic published in another type, the type published vs the type expected (the node goes on).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

__all__ = [
    "SILENCE_WARN_S",
    "SilenceWatch",
    "domain_id",
    "publisher_types",
    "topic_silence_line",
    "type_mismatch",
]

SILENCE_WARN_S = 3.0
"""Seconds without input before the one warning (a node waiting for a robot is legitimate)."""


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def domain_id(node: Any = None) -> int:
    """The node's ROS_DOMAIN_ID (its context's; else the environment's, default 0)."""
    if node is not None:
        try:
            return int(node.context.get_domain_id())
        except Exception:
            pass
    value = os.environ.get("ROS_DOMAIN_ID", "").strip()
    return int(value) if value.isdigit() else 0


def type_mismatch(published: list[str], expected: str) -> list[str]:
    """The types ``published`` on a topic other than ``expected`` (sorted, once each)."""
    return sorted({t for t in published if t != expected})


def topic_silence_line(
    command: str, topic: str, expected: str, published: list[str], domain: int, waited_s: float
) -> str:
    """The warning of ``command`` after ``waited_s`` without a message on ``topic``, from the
    types of its publishers (``get_publishers_info_by_topic``)."""
    head = f"omnical: {command}: nothing on {topic} for {waited_s:g} s (ROS_DOMAIN_ID {domain})"
    others = type_mismatch(published, expected)
    if others:
        return f"{head}: it is published as {', '.join(others)}, {command} expects {expected}"
    if published:
        return (
            f"{head}: its {len(published)} publisher(s) of {expected} send nothing or do not "
            "match (QoS); still waiting"
        )
    return (
        f"{head}: no publisher in this domain (is the robot's driver running, with the same "
        "ROS_DOMAIN_ID?); still waiting"
    )


def publisher_types(node: Any, topic: str) -> list[str]:
    """The types of the publishers of ``topic`` the node has discovered."""
    return [str(i.topic_type) for i in node.get_publishers_info_by_topic(topic)]


class SilenceWatch:
    """A thread that says ``describe()`` once (when it returns a line) after ``after_s`` without
    :meth:`seen`; it goes on checking until a line is said or it is stopped.

    Args:
        describe: the warning, given the seconds waited (None: nothing to say yet).
        after_s: the silence before the first check.
        warn: receives the line (stderr by default).
        period_s: how often it checks.
    """

    def __init__(
        self,
        describe: Callable[[float], str | None],
        after_s: float = SILENCE_WARN_S,
        warn: Callable[[str], None] = _say,
        period_s: float = 0.25,
    ) -> None:
        self.describe = describe
        self.after_s = after_s
        self.warn = warn
        self.period_s = period_s
        self.said: str | None = None
        self._last = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="silence-watch", daemon=True)

    def start(self) -> SilenceWatch:
        """Start watching (the silence counts from now)."""
        self._last = time.monotonic()
        self._thread.start()
        return self

    def seen(self) -> None:
        """Input arrived: the silence counts again from now."""
        self._last = time.monotonic()

    def stop(self) -> None:
        """Stop the thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1.0)

    def _loop(self) -> None:
        while not self._stop.wait(self.period_s):
            waited = time.monotonic() - self._last
            if waited < self.after_s:
                continue
            try:
                line = self.describe(round(waited))
            except Exception as err:
                line = f"omnical: no input for {waited:.0f} s ({type(err).__name__}: {err})"
            if line:
                self.said = line
                self.warn(line)
                return

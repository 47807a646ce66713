"""The one exception hierarchy of omnical, rooted at :class:`OmnicalError`.

A user's error (bad file, corrupt recording, impossible request): one line, exit status 2 in the
CLI; leaves also derive from the matching builtin (``ValueError``, ``OSError``).
"""

from __future__ import annotations

import errno
from typing import Final

MACHINE_ERRNOS: Final = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EROFS})
"""``OSError`` numbers that say what the machine did (disk or quota full, an I/O error, a
read-only file system), never what omnical or its user did wrong."""


class OmnicalError(Exception):
    """Root of every error omnical raises on purpose."""


class ConfigError(OmnicalError, ValueError):
    """A user file (robot description, motion script, twin, beacon map) is invalid.

    The message names the file, the field and the reason.
    """


class ChoiceError(ConfigError):
    """A value is not one of a closed set of choices (a method, a mode, a format).

    Raised by :func:`omnical.choices.parse_choice`; the message names the option, the value
    and the choices.
    """


class LimitError(OmnicalError, ValueError):
    """A request exceeds what the robot can do (speed, acceleration)."""


class RecordingError(OmnicalError, OSError):
    """A recording cannot be read or written (missing, truncated, wrong format)."""


class OutputError(OmnicalError, OSError):
    """An output path cannot be written, or writing it would destroy something not omnical's."""


class ProtocolError(OmnicalError, ValueError):
    """A byte stream violates a wire protocol (Marvelmind, Wheeltec)."""


class SafetyStopError(OmnicalError):
    """A device the experiment depends on fell silent or sent garbage while the robot moved.

    The robot has already been sent a zero command when this is raised; the message names the
    device and how long it has been silent. The CLI exits with its own status
    (``EXIT_SAFETY_STOP``, 4) and keeps what was recorded as ``RUN.partial``.
    """

    def __init__(
        self, device: str, silent_s: float, detail: str = "", *, moving: bool = True
    ) -> None:
        self.device = device
        self.silent_s = silent_s
        self.detail = detail
        self.moving = moving
        why = f" ({detail})" if detail else ""
        how_long = f"for {silent_s:.2f} s" if silent_s < 1e9 else "at all"
        when, done = ("while the robot moved", "robot stopped")
        if not moving:
            when, done = ("before the robot moved", "motion not started")
        super().__init__(f"{device}: no valid data {how_long} {when}{why}: {done}")

    def __reduce__(self) -> tuple[type[SafetyStopError], tuple[str, float, str]]:
        return (type(self), (self.device, self.silent_s, self.detail))


RunStop = KeyboardInterrupt | SafetyStopError
"""What ends a run early: Ctrl-C / SIGTERM / an abort key, or a safety stop. An experiment
stops the robot, returns what it recorded with the cause, and its caller re-raises the cause
once the recording is safe."""


class GeometryError(OmnicalError, ValueError):
    """A geometric problem is degenerate (collinear beacons, too few points for a fit)."""


class CalibrationError(OmnicalError, ValueError):
    """A calibration cannot be computed from the data given."""


__all__ = [
    "MACHINE_ERRNOS",
    "CalibrationError",
    "ChoiceError",
    "ConfigError",
    "GeometryError",
    "LimitError",
    "OmnicalError",
    "OutputError",
    "ProtocolError",
    "RecordingError",
    "RunStop",
    "SafetyStopError",
]

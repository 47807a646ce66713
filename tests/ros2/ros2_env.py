"""ROS 2 test processes: a private domain on localhost, started and stopped by PID.

``ros_env()`` is the environment of every ROS 2 process a test starts (docs/ros2.md);
``RosProcess`` starts one (``omnical ros2 ...`` or a probe script) and kills it by its PID.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from omnical.ros2.runtime import rclpy_available

HERE = Path(__file__).parent
PROBE = HERE / "ros2_probe.py"

needs_ros2 = pytest.mark.skipif(
    not rclpy_available(), reason="the [ros2] extra is not installed (make test installs it)"
)


_DOMAINS = 200
_HELD: dict[str, tuple[int, int]] = {}
"""salt → (domain, the descriptor of its lock file), held until this process ends."""


def private_domain_id(salt: str) -> int:
    """A ROS_DOMAIN_ID in 1..200 for ``salt`` (a module's or a test's name), the same for the
    same salt in this process, and no other process's: each is claimed by a lock file
    (``flock``, let go when the process ends), so the parallel suite's ROS 2 processes never
    share a domain with the networked session's (a hash of the PID alone let them, one in 100;
    a second /odom publisher spoils a campaign's stand-stills). Never a user's default, 0."""
    import fcntl

    if salt in _HELD:
        return _HELD[salt][0]
    folder = Path(tempfile.gettempdir()) / "omnical-ros2-domains"
    folder.mkdir(exist_ok=True)
    start = (os.getpid() * 31 + sum(map(ord, salt))) % _DOMAINS
    for k in range(_DOMAINS):
        domain = 1 + (start + k) % _DOMAINS
        fd = os.open(folder / f"{domain}.lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            continue
        _HELD[salt] = (domain, fd)
        return domain
    raise RuntimeError(f"every ROS_DOMAIN_ID in 1..{_DOMAINS} is held by another test process")


def ros_env(domain_id: int) -> dict[str, str]:
    """The environment of a ROS 2 test process: private domain, loopback discovery only."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["ROS_LOG_DIR"] = str(Path(tempfile.gettempdir()) / "omnical-ros2-test-logs")
    env.pop("ROS_STATIC_PEERS", None)
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def omnical_command(*args: str) -> list[str]:
    """``omnical ARGS`` as this interpreter runs it."""
    return [sys.executable, "-c", "from omnical.cli.entry import main; main()", *args]


PRIORITY_NICE = -10
"""The niceness of the robot runs' processes (where it may be raised: root): a real-time run
stops on 0.5 s without /odom, a scaled one on a tenth of that."""


def with_priority(argv: list[str]) -> list[str]:
    """``argv`` run ahead of the machine's other work: ``nice -n -10``, relative to this
    process's (−20 under ``make test``, whose networked session runs at −10; where it may not
    raise the priority, nice says so on stderr and runs it as it is; the PID stays the command's).

    On a k-times clock a scheduling stall is k times longer in robot time; a machine loaded 5–8
    times over its 2 cores stalled the twin's hedgehog stream and ``/odom`` for 0.3–0.5 s of
    wall time (issue 25's x10 campaign failed 4 times in 4 at load 10–17, and passed at nice
    −10 beside the same load). A robot's driver and omnical run so on a robot, too."""
    nice = shutil.which("nice")
    return [nice, "-n", str(PRIORITY_NICE), *argv] if nice else argv


def process_cpu_s(pid: int) -> float:
    """The CPU time (user and system, all threads) process ``pid`` has used so far, s; the
    same across an ``execve`` (the ROS 2 commands re-execute once: docs/ros2.md)."""
    stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii")
    fields = stat.rsplit(")", 1)[1].split()  # after the command name, which may hold spaces
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class RosProcess:
    """A process started in a session of its own, killed by PID (SIGINT, then SIGKILL);
    ``priority``: at :data:`PRIORITY_NICE` (see :func:`with_priority`)."""

    def __init__(
        self,
        argv: list[str],
        env: dict[str, str],
        *,
        stdin: bool = False,
        priority: bool = False,
    ) -> None:
        self.started_wall_s = time.time()
        self.proc = subprocess.Popen(
            with_priority(argv) if priority else argv,
            env=env,
            stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        self.pid = self.proc.pid

    def readline(self, timeout_s: float) -> str:
        """The next stdout line ('' at end of output or after ``timeout_s``)."""
        import select

        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout_s)
        return self.proc.stdout.readline() if ready else ""

    def stop(self, timeout_s: float = 5.0) -> tuple[int, str, str]:
        """SIGINT by PID, wait, SIGKILL if it did not end; (status, rest of stdout, stderr)."""
        if self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGINT)
        try:
            out, err = self.proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.pid, signal.SIGKILL)
            out, err = self.proc.communicate()
        return self.proc.returncode, out, err

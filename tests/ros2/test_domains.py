"""The tests' ROS_DOMAIN_IDs: one per salt in a process, never one another process holds (the
parallel suite's ROS 2 processes and the networked session's run at the same time)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from ros2_env import private_domain_id

HERE = Path(__file__).parent


def test_no_two_processes_share_a_domain() -> None:
    # salts whose characters sum 100 apart: a hash of PID and salt modulo 100 gave them one
    mine = {private_domain_id(salt) for salt in ("domains-a", "domains-ad")}
    assert len(mine) == 2 and private_domain_id("domains-a") in mine  # the same for a salt
    assert all(1 <= d <= 200 for d in mine)  # never a user's default, 0
    code = (
        f"import sys; sys.path.insert(0, {str(HERE)!r}); from ros2_env import private_domain_id; "
        "print(private_domain_id('domains-a'), private_domain_id('domains-ad'))"
    )
    # the same salts in another process, while this one holds its two: other domains
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    theirs = {int(v) for v in done.stdout.split()}
    assert len(theirs) == 2 and theirs.isdisjoint(mine)

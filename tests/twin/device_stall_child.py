"""A served twin (no vehicle port, watchdog 0.5 s) commanded from stdin, for
tests/twin/test_device_stall.py: ``VX SENT_WALL_NS`` lines are commands, ``x`` prints the
true x (m), ``stall S`` holds the loop's next tick S seconds (a publisher's stall, as
``ros2 twin``'s on a loaded host; ``stall S ack`` prints ``stalled`` as it begins; ``stall S
late`` too, and the commands read meanwhile reach the twin 5 ms after it, as a stalled
process's reader thread delivers them); stdin's end stops it. It prints ``ready`` once
serving."""

from __future__ import annotations

import sys
import time

from omnical.robot.loader import load_robot
from omnical.twin.device import DeviceConfig, TwinDeviceServer
from omnical.twin.params import load_twin


def main() -> None:
    robot = load_robot("rosy-mecanum")
    config = DeviceConfig(vehicle_port=False, watchdog_s=0.5)
    stall_s: list[tuple[float, str]] = []
    late_until: list[float] = []

    def on_tick(*_: object) -> None:
        if stall_s:
            seconds, how = stall_s.pop()
            if how == "late":
                late_until.append(time.monotonic() + seconds + 0.005)
            if how in ("ack", "late"):
                print("stalled", flush=True)
            time.sleep(seconds)

    twin = load_twin("ideal", robot)
    with TwinDeviceServer(robot, twin, config=config, on_tick=on_tick) as server:
        print("ready", flush=True)
        for line in sys.stdin:
            if line.strip() == "x":
                print(f"{server.snapshot().truth_pose_map[0]:.6f}", flush=True)
                continue
            if line.startswith("stall "):
                stall_s.append((float(line.split()[1]), line.split()[-1]))
                continue
            if late_until:
                time.sleep(max(0.0, late_until.pop() - time.monotonic()))
            vx, sent_ns = line.split()
            server.command(float(vx), 0.0, 0.0, sent_wall_ns=int(sent_ns))


if __name__ == "__main__":
    main()

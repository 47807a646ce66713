"""A served twin (no vehicle port, watchdog 0.5 s) commanded from stdin, for
tests/twin/test_device_stall.py: ``VX SENT_WALL_NS`` lines are commands, ``x`` prints the
true x (m); stdin's end stops it. It prints ``ready`` once serving."""

from __future__ import annotations

import sys

from omnical.robot.loader import load_robot
from omnical.twin.device import DeviceConfig, TwinDeviceServer
from omnical.twin.params import load_twin


def main() -> None:
    robot = load_robot("rosy-mecanum")
    config = DeviceConfig(vehicle_port=False, watchdog_s=0.5)
    with TwinDeviceServer(robot, load_twin("ideal", robot), config=config) as server:
        print("ready", flush=True)
        for line in sys.stdin:
            if line.strip() == "x":
                print(f"{server.twin.ground_truth_pose[0]:.6f}", flush=True)
                continue
            vx, sent_ns = line.split()
            server.command(float(vx), 0.0, 0.0, sent_wall_ns=int(sent_ns))


if __name__ == "__main__":
    main()

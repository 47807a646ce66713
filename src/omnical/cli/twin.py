"""``omnical twin serve``: the digital twin behind two pseudo-terminals, as the firmware would be.

Wall-clock time until Ctrl-C or SIGTERM, then ``--truth-out`` (truth, odometry, IMU); ``--time-scale
K`` (hidden, for tests) runs it K times faster, and the host must run at the same K.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors
from omnical.cli.help_layout import App
from omnical.cli.monitor_options import (
    MonitorOption,
    monitor_link,
    monitor_target,
    serve_monitored,
)
from omnical.cli.options import Beacons, Robot, Seed

__all__ = ["app", "serve"]

app = App(
    name="twin",
    help="The digital twin as a device (pseudo-terminals).",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


@app.command()
def serve(
    robot: Robot = "rosy-mecanum",
    twin: Annotated[str, typer.Option(help="Twin YAML, or 'default' / 'ideal'.")] = "default",
    seed: Seed = 0,
    beacons: Beacons = None,
    baud: Annotated[int, typer.Option(help="Vehicle controller baud rate (byte pacing).")] = 115200,
    hedge_baud: Annotated[int, typer.Option(help="Hedgehog baud rate (byte pacing).")] = 115200,
    watchdog: Annotated[
        str,
        typer.Option(help="Command watchdog: 'off' (stock firmware) or a timeout in s."),
    ] = "off",
    truth_out: Annotated[
        Path | None, typer.Option(help="Write the twin's truth bag here when stopped.")
    ] = None,
    time_scale: Annotated[
        float,
        typer.Option(
            hidden=True,
            help="Tests only: run the device this many times faster than the wall clock.",
        ),
    ] = 1.0,
    monitor: MonitorOption = None,
) -> None:
    """Serve the twin on two pseudo-terminals until stopped."""
    with handled_errors():
        import math

        from omnical.bags.bag import check_bag_output, write_bag
        from omnical.errors import ConfigError
        from omnical.ips.beacons import load_beacon_map
        from omnical.robot.loader import available_presets, load_robot
        from omnical.twin.device import DeviceConfig, TwinDeviceServer
        from omnical.twin.params import load_twin

        if watchdog == "off":
            timeout = None
        else:
            try:
                timeout = float(watchdog)
            except ValueError:
                timeout = math.nan
            if not (math.isfinite(timeout) and timeout > 0.0):
                msg = f"--watchdog {watchdog!r}: 'off' or a timeout in seconds (> 0)"
                raise ConfigError(msg) from None
        if not (math.isfinite(time_scale) and 0.1 <= time_scale <= 100.0):
            msg = f"--time-scale {time_scale:g}: give robot seconds per wall second from 0.1 to 100"
            raise ConfigError(msg)
        if truth_out is not None:
            check_bag_output(truth_out, overwrite=False)
        target = monitor_target(monitor)  # a bad --monitor before the ptys are up
        description = load_robot(robot)
        source = "preset" if robot in available_presets() else f"file {robot}"
        # on stderr: stdout's first two lines are the device paths scripts read
        typer.echo(f"robot: {description.name} ({source}), twin: {twin}", err=True)
        bmap = load_beacon_map(beacons) if beacons is not None else None
        params = load_twin(twin, description, bmap)
        config = DeviceConfig(
            baudrate=baud, hedge_baudrate=hedge_baud, watchdog_s=timeout, time_scale=time_scale
        )
        server = TwinDeviceServer(
            description,
            params,
            seed=seed,
            beacons=bmap,
            config=config,
            on_stall=_stall_warning(time_scale),
        )
        server.start()
        try:
            typer.echo(f"vehicle controller: {server.vehicle_path}", err=False)
            typer.echo(f"hedgehog: {server.hedge_path}", err=False)
            # the commands as they work against this server: its beacons, its clock, its monitor
            extra = "" if time_scale == 1.0 else f" --time-scale {time_scale:g}"
            extra += "" if monitor is None else f" --monitor {monitor}"
            served = "" if beacons is None else f" --beacons {beacons}"
            typer.echo(
                f"  omnical run SCRIPT --robot serial:{server.vehicle_path} "
                f"--hedge serial:{server.hedge_path} --beacons {beacons or 'default'}{extra} "
                "--out RUN.mcap",
                err=False,
            )
            typer.echo(
                f"  omnical calibrate campaign --robot serial:{server.vehicle_path} "
                f"--hedge serial:{server.hedge_path} --model {robot}{served}{extra} --out DIR",
                err=False,
            )
            import sys

            sys.stdout.flush()
            with monitor_link(target, "omnical twin serve", reset=False) as link:
                serve_monitored(server, link, bmap)
        finally:
            server.stop()
            if truth_out is not None:
                written = write_bag(server.recording(), truth_out)
                typer.echo(f"wrote {written}", err=True)


def _stall_warning(time_scale: float) -> Callable[[float, float], None]:
    """A warning on stderr when the served twin paused: at most one each 10 s unless a longer
    pause comes (the one that may have stopped a run), with the count of those not said."""
    import os
    import time

    from omnical.services.hil import SCALED_STALL_S

    limit = "0.15 s" if time_scale == 1.0 else f"{SCALED_STALL_S:g} s of wall time (a scaled clock)"
    said_s, longest_s, unsaid = -math.inf, 0.0, 0

    def warn(t_s: float, paused_s: float) -> None:
        nonlocal said_s, longest_s, unsaid
        now = time.monotonic()
        if now - said_s < 10.0 and paused_s <= longest_s:
            unsaid += 1
            return
        more = f" ({unsaid} shorter pause(s) not said since the last warning)" if unsaid else ""
        load = os.getloadavg()[0]
        typer.echo(
            f"omnical twin serve: warning: the twin paused {paused_s:.2f} s at t={t_s:.1f} s"
            f"{more}: this machine is busy (load {load:.1f} on {os.cpu_count()} cores); a "
            f"run watching its vehicle controller stops the robot after {limit} of silence",
            err=True,
        )
        said_s, longest_s, unsaid = now, paused_s, 0

    return warn

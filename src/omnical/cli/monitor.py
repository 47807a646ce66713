"""``omnical monitor [RUN]``: a live view of a run in the browser, or the replay of a recording.

One page and one WebSocket on 127.0.0.1 (``--host`` for more, then with a token in the URL);
runs stream to it with ``--monitor [HOST:]PORT``. Needs the extra: ``pip install 'omnical[web]'``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from omnical.cli.errors import handled_errors

__all__ = ["monitor"]

_EXTRA_MODULES = ("starlette", "uvicorn", "websockets")


def monitor(
    run: Annotated[
        Path | None,
        typer.Argument(help="A recording to replay (RUN.mcap, a ROS 1 bag); none: the live view."),
    ] = None,
    host: Annotated[
        str,
        typer.Option(
            help="Address to listen on; anything but loopback requires a token in the URL."
        ),
    ] = "127.0.0.1",
    port: Annotated[
        int, typer.Option(help="Port of the page and of --monitor (0: any free).")
    ] = 8765,
    map_yaml: Annotated[
        Path | None,
        typer.Option(
            "--map",
            help="Occupancy map under the view: map_server YAML or a shipped world (lab-8x6, "
            "warehouse-20x20).",
        ),
    ] = None,
    beacons: Annotated[
        str | None, typer.Option(help="Beacon map YAML or 'default' (else the run's own).")
    ] = None,
    token: Annotated[
        str | None,
        typer.Option(help="The URL token (default: a fresh one when --host is not loopback)."),
    ] = None,
    batch: Annotated[
        int,
        typer.Option(hidden=True, help="Benchmarks: most frames per WebSocket message (1: one)."),
    ] = 32,
) -> None:
    """Serve a live view of runs (``--monitor`` on run, calibrate campaign, navigate, twin serve,
    ros2 twin, ros2 correct, ros2 locate, ros2 map) or the replay of RUN, on one page: status,
    map, time plots and events."""
    with handled_errors():
        _monitor(run, host, port, map_yaml, beacons, token, batch)


def _check_extra() -> None:
    import importlib.util

    from omnical.errors import ConfigError

    missing = [m for m in _EXTRA_MODULES if importlib.util.find_spec(m) is None]
    if missing:
        msg = (
            f"omnical monitor needs the web extra ({', '.join(missing)} missing): "
            "pip install 'omnical[web]'"
        )
        raise ConfigError(msg)


def _monitor(
    run: Path | None,
    host: str,
    port: int,
    map_yaml: Path | None,
    beacons: str | None,
    token: str | None,
    batch: int = 32,
) -> None:
    import errno
    import secrets
    import socket
    import sys

    from omnical.cli.output import say
    from omnical.errors import ConfigError

    _check_extra()
    from omnical.web.hub import Hub
    from omnical.web.protocol import beacons_payload, is_loopback, map_payload
    from omnical.web.server import serve

    if batch < 1:
        msg = f"--batch {batch}: at least 1 frame a message"
        raise ConfigError(msg)
    if not 0 <= port <= 65535:
        msg = f"--port {port}: a port is within 0–65535"
        raise ConfigError(msg)
    if token is None and not is_loopback(host):
        token = secrets.token_urlsafe(18)
    hub = Hub()
    if map_yaml is not None:
        from omnical.navigation.map_io import load_map, resolve_world

        grid = load_map(resolve_world(map_yaml))
        hub.publish("map", map_payload(grid.cells, grid.resolution_m, grid.origin), latch=True)
    bmap = None
    if beacons is not None:
        from omnical.ips.beacons import default_beacon_map, load_beacon_map

        bmap = default_beacon_map() if beacons == "default" else load_beacon_map(beacons)
        hub.publish("beacons", beacons_payload(bmap.addresses, bmap.positions_m), latch=True)
    if run is not None:
        from omnical.web.replay import load_replay

        data = load_replay(run, bmap)
        hub.publish("recording", data, latch=True)
        if data["beacons"] is not None and beacons is None:
            hub.publish("beacons", data["beacons"], latch=True)
        say(f"replaying {run}: {data['duration_s']:.1f} s, {data['rows']} rows")
        if data["note"] is not None:
            say(data["note"])

    def ready(bound: int) -> None:
        query = f"?token={token}" if token else ""
        anywhere = host in {"0.0.0.0", "::", ""}  # every address: the URL names this machine
        name = socket.gethostname() if anywhere else host
        shown = f"[{name}]" if ":" in name else name
        url = f"http://{shown}:{bound}/{query}"
        say(f"omnical monitor: {url}" + (" (listening on every address)" if anywhere else ""))
        if run is None:  # a bare port is 127.0.0.1 without a token: else the whole URL
            local = f"http://127.0.0.1:{bound}/{query}" if anywhere else url
            where = str(bound) if host == "127.0.0.1" and not token else f"'{local}'"
            say(f"  stream a run to it: omnical run SCRIPT --out RUN.mcap --monitor {where}")
        say("  Ctrl-C stops it")
        sys.stdout.flush()

    try:
        serve(hub, host, port, token=token, on_ready=ready, batch=batch)
    except OSError as err:
        if err.errno == errno.EADDRINUSE:
            msg = f"--port {port}: address {host}:{port} already in use (another monitor?)"
            raise ConfigError(msg) from None
        if err.errno in {errno.EADDRNOTAVAIL, errno.EAFNOSUPPORT} or isinstance(
            err, socket.gaierror
        ):
            msg = f"--host {host}: not an address of this machine ({err.strerror or err})"
            raise ConfigError(msg) from None
        raise

"""``--monitor [HOST:]PORT``: a command streams its live run to ``omnical monitor``.

The option, :func:`monitor_target` (checked before anything starts), :func:`monitor_link` (the
run's :class:`~omnical.web.tee.MonitorLink`, or None) and :func:`serve_monitored` (a served twin
fed to it); streaming needs only the standard library and numpy."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Annotated, Any

import typer

if TYPE_CHECKING:
    from omnical.web.protocol import MonitorTarget
    from omnical.web.tee import MonitorLink

__all__ = [
    "MonitorOption",
    "driver_status",
    "latch_scene",
    "monitor_link",
    "monitor_target",
    "serve_monitored",
    "tee_to",
]

MonitorOption = Annotated[
    str | None,
    typer.Option(
        "--monitor",
        metavar="PORT",
        help="Stream the run live to 'omnical monitor' on [HOST:]PORT (or the URL it printed, "
        "with its token); the run never waits for it.",
    ),
]


def monitor_target(spec: str | None) -> MonitorTarget | None:
    """``--monitor``'s target (None without the option), parsed before a command starts devices.

    Raises:
        ConfigError: not [HOST:]PORT nor the monitor's URL.
    """
    if spec is None:
        return None
    from omnical.web.protocol import parse_monitor_target

    return parse_monitor_target(spec)


@contextmanager
def monitor_link(
    spec: str | MonitorTarget | None, source: str, *, reset: bool = True
) -> Iterator[MonitorLink | None]:
    """The link to the monitor ``spec`` names (None: no ``--monitor``), started, and closed on
    leaving (what is queued is sent for up to a second). ``reset``: the page starts afresh."""
    target = monitor_target(spec) if isinstance(spec, str) else spec
    if target is None:
        yield None
        return
    from omnical.cli.output import say
    from omnical.web.tee import MonitorLink

    link = MonitorLink(target, source, reset=reset)
    say(f"streaming to the monitor at http://{target.host}:{target.port}/ (--monitor)")
    link.start()
    try:
        yield link
    finally:
        link.close()


def tee_to(sink: object, link: MonitorLink | None) -> object:
    """``sink`` teeing its rows to ``link`` (``sink`` itself without a link)."""
    if link is None:
        return sink
    from omnical.web.tee import MonitorTee

    return MonitorTee(sink, link)  # type: ignore[arg-type]


def latch_scene(
    link: MonitorLink | None,
    *,
    beacons: object | None = None,
    start_pose_map: tuple[float, float, float] | None = None,
    hedge_offset_m: tuple[float, ...] | None = None,
) -> None:
    """Send the static data of a run once known: the beacons, the odometry's origin in the map
    (the start pose) and the hedgehog's offset on the robot."""
    if link is None:
        return
    from omnical.ips.beacons import BeaconMap
    from omnical.web.protocol import beacons_payload

    if isinstance(beacons, BeaconMap):
        link.latch("beacons", beacons_payload(beacons.addresses, beacons.positions_m))
    if start_pose_map is not None:
        x, y, yaw = (float(v) for v in start_pose_map)
        offset = None if hedge_offset_m is None else [float(v) for v in hedge_offset_m[:2]]
        link.latch("origin", {"x": x, "y": y, "yaw": yaw, "offset": offset, "from": "start pose"})


@contextmanager
def driver_status(
    link: MonitorLink | None, driver: object, host_watchdog_s: float | None
) -> Iterator[None]:
    """While inside: the vehicle controller's battery, stop flag and the host watchdog sent to
    the monitor twice a second, from a thread of its own (``read_state`` takes the driver's
    lock only to copy its last frame)."""
    if link is None:
        yield
        return
    import threading
    import time

    stop = threading.Event()

    def feed() -> None:
        while not stop.wait(0.5):
            state: Any = driver.read_state()  # type: ignore[attr-defined]
            tripped = bool(getattr(state, "host_watchdog_tripped", False))
            watchdog = "off" if host_watchdog_s is None else f"host {host_watchdog_s:g} s"
            link.send(
                "status",
                {"t": time.time(), "battery_v": getattr(state, "battery_v", None),
                 "stop": bool(getattr(state, "stop_flag", False)),
                 "watchdog": watchdog + (", TRIPPED" if tripped else "")},
            )  # fmt: skip

    thread = threading.Thread(target=feed, name="monitor-status", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(timeout=1.0)


def serve_monitored(
    server: Any,
    link: MonitorLink | None,
    beacons: object = None,
    serve: Callable[[], None] | None = None,
) -> None:
    """``serve()`` (default: ``server.serve_forever``) in the foreground; with a link, the served
    twin's state (``server``, a :class:`~omnical.twin.device.TwinDeviceServer`) fed to it from a
    thread of its own (:func:`~omnical.web.device_feed.feed_device`)."""
    run: Callable[[], None] = serve if serve is not None else server.serve_forever
    if link is None:
        run()
        return
    import threading

    from omnical.web.device_feed import feed_device

    stop = threading.Event()
    feeder = threading.Thread(
        target=feed_device, args=(server, link, stop), kwargs={"beacons": beacons},
        name="monitor-feed", daemon=True,
    )  # fmt: skip
    feeder.start()
    try:
        run()
    finally:
        stop.set()
        feeder.join(timeout=1.0)

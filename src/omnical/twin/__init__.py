"""The digital twin: plant with imperfections, vehicle-controller firmware, sensors, simulated IPS."""

from omnical.twin.clock import TwinClock
from omnical.twin.params import TwinParams, default_twin, load_twin, parse_twin
from omnical.twin.simulator import DigitalTwin, TwinLog

__all__ = [
    "DigitalTwin",
    "TwinClock",
    "TwinLog",
    "TwinParams",
    "default_twin",
    "load_twin",
    "parse_twin",
]

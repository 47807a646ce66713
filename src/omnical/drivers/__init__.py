"""Drivers for real hardware behind the experiment ports (the hardware-in-the-loop edge).

* :mod:`omnical.drivers.wheeltec` — the Wheeltec vehicle-controller serial protocol as pure
  functions: 11-byte command frames, 24-byte status frames, a resynchronising status reader with
  checksum *and* plausibility checks, and the firmware-side command parser (for the twin device).
* :mod:`omnical.drivers.wheeltec_serial` — :class:`WheeltecRobot`, the :class:`Robot` port over
  pyserial (fixed-rate command thread, odometry from the status twist, stale detection, zero
  command on stop / close / exception / signal, host-side watchdog).
* :mod:`omnical.drivers.hedgehog` — :class:`SerialHedgehog`, the live Marvelmind position source
  recording the topics the twin records.
* :mod:`omnical.drivers.compensation` — :class:`CompensatingRobot`, the seven factors applied
  host-side for stock firmware.
* :mod:`omnical.drivers.safety` — coverage and allowed-area checks of a procedure's path.

This package sits at the edge, beside :mod:`omnical.twin` (which uses the pure codec for its
device server); it never imports the twin.
"""

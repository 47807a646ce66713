"""Drivers for real hardware behind the experiment ports (the hardware-in-the-loop edge).

``wheeltec`` (the codec), ``wheeltec_serial`` (the Robot port over pyserial), ``hedgehog`` (live
Marvelmind), ``compensation`` (host-side factors), ``safety`` and ``watchdog``; never the twin.
"""

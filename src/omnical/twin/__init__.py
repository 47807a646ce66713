"""The digital twin: plant with imperfections, vehicle-controller firmware, sensors, simulated IPS."""

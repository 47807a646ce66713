"""Control: PID (seed 003 form), Ziegler–Nichols, command limits, controllers, the loop on any Robot."""

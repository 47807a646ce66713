"""omnical: kinematics, digital twin, indoor positioning and calibration for omnidirectional robots."""

from omnical.errors import OmnicalError

__all__ = ["OmnicalError", "__version__"]
__version__ = "0.1.0"

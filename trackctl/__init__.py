"""trackctl: offline indoor tracking and robot localization over MCAP sensor logs."""

from trackctl.errors import TrackctlError

__version__ = "0.1.0"
__all__ = ["TrackctlError", "__version__"]

"""BridgeLoc (dissertation §4.2): robot localization by bridging infrastructure and robot camera
views through simple rotation-symmetric tags, with an EKF over odometry for blind spots."""

from trackctl.bridgeloc.tags import (
    BORDER_RATIO,
    Mount,
    Placement,
    PracticalTag,
    count_practical,
    count_universal,
    enumerate_practical,
    enumerate_universal,
    theorem5,
    theorem6,
)

__all__ = [
    "BORDER_RATIO",
    "Mount",
    "Placement",
    "PracticalTag",
    "count_practical",
    "count_universal",
    "enumerate_practical",
    "enumerate_universal",
    "theorem5",
    "theorem6",
]

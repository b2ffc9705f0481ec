"""The runner that drives a calibration policy on an arm holding a camera + IMU and records it.

Kept for old imports: new code imports from ``vical.collection.runner``.
"""

from vical.collection.runner import *  # noqa: F403
from vical.collection.runner import (  # noqa: F401
    CENTRE_FRACTIONS,
    OUTSIDE_MARGIN,
    R_TOOL_CAMERA,
    Alignment,
    CollectionStopped,
    Collector,
    CollectResult,
    Limits,
    RobotEpisode,
    SensorStream,
)

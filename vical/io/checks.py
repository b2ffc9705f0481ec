"""Checks of the timestamps, IMU units and rates of data read from files, and the fixes they apply.

Kept for old imports: new code imports from ``vical.io.sample_checks``.
"""

from vical.io.sample_checks import *  # noqa: F403
from vical.io.sample_checks import (  # noqa: F401
    ACCEL_NORM_RANGE,
    ACCEL_UNITS,
    GYRO_UNITS,
    MAX_DT_NS,
    MAX_GYRO_RAD_S,
    MIN_DT_NS,
    MIN_MOTION_RAD_S,
    RATE_TOLERANCE,
    FormatWarning,
    check_camera_rates,
    check_sampling,
    parse_timestamp_ns,
    scale_imu,
    sort_and_dedupe,
    warn,
)

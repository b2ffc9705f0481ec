"""Typed containers for sensor data: IMU samples, camera frames, sensor truth, recordings.

Kept for old imports: new code imports from ``vical.data`` or from the module that holds the name:
``errors``, ``sample_arrays``, ``imu``, ``camera_frames``, ``sensor_truth``, ``trajectory``, ``sensor_recording``.
"""

from vical.data.camera_frames import *  # noqa: F403
from vical.data.camera_frames import (  # noqa: F401
    CameraFrames,
)
from vical.data.errors import *  # noqa: F403
from vical.data.errors import (  # noqa: F401
    DataError,
)
from vical.data.imu import *  # noqa: F403
from vical.data.imu import (  # noqa: F401
    ImuNoise,
    ImuSamples,
)
from vical.data.sample_arrays import *  # noqa: F403
from vical.data.sample_arrays import (  # noqa: F401
    NS_PER_S,
    as_timestamps,
    as_vectors,
    seconds_since,
)
from vical.data.sensor_recording import *  # noqa: F403
from vical.data.sensor_recording import (  # noqa: F401
    CAMERA_NAME,
    FIRST_CAMERA,
    Recording,
)
from vical.data.sensor_truth import *  # noqa: F403
from vical.data.sensor_truth import (  # noqa: F401
    SensorTruth,
)
from vical.data.trajectory import *  # noqa: F403
from vical.data.trajectory import (  # noqa: F401
    PathProfile,
    Trajectory,
)

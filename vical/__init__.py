"""vical: learned data collection and factor-graph calibration for camera + IMU sensors.

The public API (``docs/api.md``) is what ``PUBLIC`` names: reading and writing recordings and Kalibr's files,
calibrating, collecting in simulation. ``import vical`` stays light (every console script imports it before its
command's heavy imports): a name is imported from its module when first used. The modules behind the names can
be imported too, but only what ``PUBLIC`` lists is kept stable; the rest may move.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

# name -> the module that defines it: the public API, in one place.
PUBLIC = {
    # what a sensor recorded, and the files Kalibr and vical read and write
    "Recording": "vical.data",
    "Target": "vical.data",
    "ImuNoise": "vical.data",
    "CameraModel": "vical.geometry",
    "open_recording": "vical.io.sources",
    "load_recording": "vical.io.recording",
    "save_recording": "vical.io.recording",
    "read_target_yaml": "vical.io.kalibr",
    "read_imu_yaml": "vical.io.kalibr",
    "read_camchain": "vical.io.kalibr",
    "write_target_yaml": "vical.io.kalibr",
    "write_imu_yaml": "vical.io.kalibr",
    "write_camchain_imucam": "vical.io.kalibr",
    # calibrating
    "calibrate": "vical.api",
    "calibrate_rig": "vical.calib.solve.pipeline",
    "RigCalibration": "vical.calib.solve.pipeline",
    "CalibrationResult": "vical.calib.result",
    "CalibrationError": "vical.calib.errors",
    "ViOptions": "vical.calib.solve.visual_inertial",
    "calibration_errors": "vical.calib.metrics",
    # collecting
    "collect_in_simulation": "vical.api",
    "SimulatedCollection": "vical.api",
}

__all__ = sorted(PUBLIC)


def __getattr__(name: str) -> Any:
    if name not in PUBLIC:
        raise AttributeError(f"module 'vical' has no attribute {name!r}")
    value = getattr(importlib.import_module(PUBLIC[name]), name)
    globals()[name] = value  # imported once
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *PUBLIC])

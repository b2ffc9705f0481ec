"""vical: learned data collection and factor-graph calibration for camera + IMU sensors."""

__version__ = "0.1.0"

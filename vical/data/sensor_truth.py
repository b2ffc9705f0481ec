"""The true (simulated) or reference parameters of a camera + IMU sensor (``SensorTruth``).

Frames follow ``docs/conventions.md``: ``T_a_b`` maps frame-b points into frame a.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vical.data.errors import DataError
from vical.data.imu import ImuNoise
from vical.data.imu_grade import ImuGrade
from vical.data.imu_model import ImuIntrinsics
from vical.geometry.camera import CameraModel


@dataclass(frozen=True)
class SensorTruth:
    """The true (simulated) or reference parameters of a camera + IMU sensor.

    Attributes:
        camera: the camera model with its intrinsics and distortion.
        T_cam_imu: (4, 4) maps IMU-frame points into the camera (OpenCV) frame.
        time_offset: [s] Kalibr's ``timeshift_cam_imu``: an image stamped ``t_cam`` was taken
            at IMU time ``t_cam + time_offset``.
        imu_noise: the IMU noise model.
        gyro_bias: (3,) [rad/s] initial gyro bias; accel_bias: (3,) [m/s^2] initial accel bias.
        imu_intrinsics: the IMU's scale, misalignment and g-sensitivity (identity: exact axes).
        imu_grade: the grade ``imu_intrinsics`` were drawn from (``vical.data.imu_grade``): what the sensor declares
            of them (``calibrated``: exact axes).
        line_delay: [s/row] the camera's rolling shutter: image row ``v`` is exposed ``line_delay * v`` after
            the image's timestamp (row 0 at the timestamp, ``docs/formats.md``); 0: a global shutter.
    """

    camera: CameraModel
    T_cam_imu: np.ndarray
    time_offset: float = 0.0
    imu_noise: ImuNoise = field(default_factory=ImuNoise)
    gyro_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    imu_intrinsics: ImuIntrinsics = field(default_factory=ImuIntrinsics)
    line_delay: float = 0.0
    imu_grade: ImuGrade = field(default_factory=ImuGrade)

    def __post_init__(self) -> None:
        T = np.asarray(self.T_cam_imu, dtype=np.float64)
        if T.shape != (4, 4):
            raise DataError(f"T_cam_imu must be 4 x 4, got {T.shape}")
        R = T[:3, :3]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise DataError("T_cam_imu rotation block is not a rotation matrix")
        object.__setattr__(self, "T_cam_imu", T)
        object.__setattr__(self, "gyro_bias", np.asarray(self.gyro_bias, dtype=np.float64).reshape(3))
        object.__setattr__(self, "accel_bias", np.asarray(self.accel_bias, dtype=np.float64).reshape(3))

    def to_dict(self) -> dict:
        return {
            "camera": self.camera.to_dict(),
            "T_cam_imu": self.T_cam_imu.tolist(),
            "time_offset": float(self.time_offset),
            "imu_noise": self.imu_noise.to_dict(),
            "gyro_bias": self.gyro_bias.tolist(),
            "accel_bias": self.accel_bias.tolist(),
            "imu_intrinsics": self.imu_intrinsics.to_dict(),
            "line_delay": float(self.line_delay),
            "imu_grade": self.imu_grade.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> SensorTruth:
        return cls(
            camera=CameraModel.from_dict(d["camera"]),
            T_cam_imu=np.asarray(d["T_cam_imu"], dtype=np.float64),
            time_offset=float(d["time_offset"]),
            imu_noise=ImuNoise.from_dict(d["imu_noise"]),
            gyro_bias=np.asarray(d.get("gyro_bias", [0, 0, 0]), dtype=np.float64),
            accel_bias=np.asarray(d.get("accel_bias", [0, 0, 0]), dtype=np.float64),
            imu_intrinsics=ImuIntrinsics.from_dict(d["imu_intrinsics"]) if "imu_intrinsics" in d else ImuIntrinsics(),
            line_delay=float(d.get("line_delay", 0.0)),
            imu_grade=ImuGrade(**d.get("imu_grade", {})),
        )

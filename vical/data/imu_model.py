"""IMU intrinsics: scale factors, axis misalignment and the gyro's g-sensitivity (Kalibr's ``scale-misalignment``).

A real IMU reads, besides noise and biases (``ImuNoise``)::

    accel_meas = M_a a                       a: specific force in the IMU frame [m/s^2]
    gyro_meas  = M_g C w + A C a             w: angular rate in the IMU frame [rad/s]

``M_a`` and ``M_g`` are lower triangular (their diagonals the scale factors, the entries below it the
axis misalignments [rad]), ``C`` (``C_gyro_i``) rotates the IMU frame into the gyro's, and ``A``
[(rad/s)/(m/s^2)] is the gyro's sensitivity to specific force. The IMU frame is the
accelerometer's (its x axis along the accelerometer's x, its y in the accelerometer's x-y plane),
so a lower-triangular ``M_a`` leaves the frame's orientation to the camera-IMU extrinsic. These are
Kalibr's ``accelerometers: M`` and ``gyroscopes: M, A, C_gyro_i``.

The parameter vector of the calibration (``vector``, ``from_vector``; small numbers around zero)::

    [accel scale - 1 (x y z), accel misalignment (yx zx zy), gyro scale - 1 (x y z),
     gyro misalignment (yx zx zy), C_gyro_i rotation vector (x y z) [rad], A (9, row by row)]
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LOWER = (np.array([1, 2, 2]), np.array([0, 0, 1]))  # (row, column) of the misalignments yx, zx, zy
AXIS_NAMES = ("x", "y", "z")
MISALIGNMENT_NAMES = ("yx", "zx", "zy")
SCALE_MISALIGNMENT_SIZE = 15
G_SENSITIVITY_SIZE = 9


def _rotation(rotvec: np.ndarray) -> np.ndarray:
    """Rodrigues' formula (3, 3) of a rotation vector (3,) [rad]."""
    theta = float(np.linalg.norm(rotvec))
    K = np.array([[0, -rotvec[2], rotvec[1]], [rotvec[2], 0, -rotvec[0]], [-rotvec[1], rotvec[0], 0]])
    if theta < 1e-12:
        return np.eye(3) + K
    return np.eye(3) + np.sin(theta) / theta * K + (1 - np.cos(theta)) / theta**2 * (K @ K)


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) [rad] of a rotation matrix (angles below pi)."""
    angle = np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
    return axis if angle < 1e-12 else axis * angle / np.sin(angle)


def _lower(scale_minus_one: np.ndarray, misalignment: np.ndarray) -> np.ndarray:
    M = np.diag(1.0 + np.asarray(scale_minus_one, dtype=float))
    M[LOWER] = misalignment
    return M


@dataclass(frozen=True)
class ImuIntrinsics:
    """Scale, misalignment and g-sensitivity of an IMU (see the module docstring); identity by default.

    Attributes:
        M_accel: (3, 3) lower triangular [-].
        M_gyro: (3, 3) lower triangular [-].
        C_gyro_i: (3, 3) rotation from the IMU (accelerometer) frame to the gyro frame.
        A_gyro: (3, 3) g-sensitivity [(rad/s)/(m/s^2)].
    """

    M_accel: np.ndarray = field(default_factory=lambda: np.eye(3))
    M_gyro: np.ndarray = field(default_factory=lambda: np.eye(3))
    C_gyro_i: np.ndarray = field(default_factory=lambda: np.eye(3))
    A_gyro: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))

    def __post_init__(self) -> None:
        for name in ("M_accel", "M_gyro", "C_gyro_i", "A_gyro"):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != (3, 3) or not np.all(np.isfinite(value)):
                raise ValueError(f"ImuIntrinsics.{name} must be a finite 3 x 3 matrix, got {value.tolist()}")
            object.__setattr__(self, name, value)
        for name in ("M_accel", "M_gyro"):
            value = getattr(self, name)
            if np.any(np.triu(value, 1) != 0) or np.any(np.diag(value) <= 0):
                raise ValueError(f"ImuIntrinsics.{name} must be lower triangular with a positive diagonal")
        C = self.C_gyro_i
        if not np.allclose(C @ C.T, np.eye(3), atol=1e-6) or np.linalg.det(C) < 0:
            raise ValueError("ImuIntrinsics.C_gyro_i must be a rotation matrix")

    # ------------------------------------------------------------------ the model
    def distort(self, gyro: np.ndarray, accel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What the IMU reads (N, 3), (N, 3) for the true rates [rad/s] and specific forces [m/s^2] (N, 3)."""
        accel = np.asarray(accel, dtype=float)
        measured_gyro = np.asarray(gyro, dtype=float) @ (self.M_gyro @ self.C_gyro_i).T
        return measured_gyro + accel @ (self.A_gyro @ self.C_gyro_i).T, accel @ self.M_accel.T

    def correct(self, gyro: np.ndarray, accel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The true rates and specific forces (N, 3), (N, 3) of readings (N, 3): ``distort`` inverted."""
        accel_true = np.linalg.solve(self.M_accel, np.asarray(accel, dtype=float).T).T
        rest = np.asarray(gyro, dtype=float) - accel_true @ (self.A_gyro @ self.C_gyro_i).T
        return np.linalg.solve(self.M_gyro @ self.C_gyro_i, rest.T).T, accel_true

    # ------------------------------------------------------------------ parameters
    def vector(self, g_sensitivity: bool = False) -> np.ndarray:
        """(15,) or (24,) with ``g_sensitivity``: the calibration's parameters (module docstring)."""
        parts = [
            np.diag(self.M_accel) - 1.0,
            self.M_accel[LOWER],
            np.diag(self.M_gyro) - 1.0,
            self.M_gyro[LOWER],
            _rotation_vector(self.C_gyro_i),
        ]
        return np.concatenate(parts + ([self.A_gyro.reshape(-1)] if g_sensitivity else []))

    @classmethod
    def from_vector(cls, theta: np.ndarray) -> ImuIntrinsics:
        """The intrinsics of a (15,) or (24,) parameter vector (``vector``)."""
        theta = np.asarray(theta, dtype=float)
        if theta.shape not in ((SCALE_MISALIGNMENT_SIZE,), (SCALE_MISALIGNMENT_SIZE + G_SENSITIVITY_SIZE,)):
            raise ValueError(f"IMU intrinsics take 15 or 24 parameters, got {theta.shape}")
        A = theta[15:].reshape(3, 3) if len(theta) > 15 else np.zeros((3, 3))
        return cls(_lower(theta[0:3], theta[3:6]), _lower(theta[6:9], theta[9:12]), _rotation(theta[12:15]), A)

    @staticmethod
    def parameter_names(g_sensitivity: bool = False) -> list[str]:
        """Names of ``vector``'s entries, as the calibration result lists them."""
        names = [f"accel_scale_{a}" for a in AXIS_NAMES] + [f"accel_misalign_{m}" for m in MISALIGNMENT_NAMES]
        names += [f"gyro_scale_{a}" for a in AXIS_NAMES] + [f"gyro_misalign_{m}" for m in MISALIGNMENT_NAMES]
        names += [f"gyro_rot_{a}" for a in AXIS_NAMES]
        if g_sensitivity:
            names += [f"g_sens_{r}{c}" for r in AXIS_NAMES for c in AXIS_NAMES]
        return names

    def is_identity(self) -> bool:
        """Whether the IMU reads the truth (unit scales, no misalignment, no g-sensitivity)."""
        return bool(np.allclose(self.vector(True), 0.0, atol=1e-15))

    def to_dict(self) -> dict:
        return {name: getattr(self, name).tolist() for name in ("M_accel", "M_gyro", "C_gyro_i", "A_gyro")}

    @classmethod
    def from_dict(cls, d: dict) -> ImuIntrinsics:
        return cls(**{name: np.asarray(d[name], dtype=float) for name in ("M_accel", "M_gyro", "C_gyro_i", "A_gyro")})

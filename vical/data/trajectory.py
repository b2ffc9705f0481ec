"""The ground-truth motion: the IMU's trajectory (``Trajectory``) and the end effector's path over time
(``PathProfile``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vical.data.errors import DataError
from vical.data.sample_arrays import as_timestamps, as_vectors


@dataclass(frozen=True)
class Trajectory:
    """Ground-truth IMU trajectory in the world frame (IMU clock).

    Attributes:
        t: (K,) int64 [ns] timestamps.
        T_world_imu: (K, 4, 4) IMU pose (maps IMU-frame points into the world frame).
        v_world: (K, 3) [m/s] IMU-origin velocity in the world frame.
        omega_imu: (K, 3) [rad/s] angular velocity in the IMU frame.
    """

    t: np.ndarray
    T_world_imu: np.ndarray
    v_world: np.ndarray
    omega_imu: np.ndarray

    def __post_init__(self) -> None:
        t = as_timestamps(self.t, "Trajectory.t")
        object.__setattr__(self, "t", t)
        T = np.asarray(self.T_world_imu, dtype=np.float64)
        if T.shape != (len(t), 4, 4):
            raise DataError(f"Trajectory.T_world_imu must be ({len(t)}, 4, 4), got {T.shape}")
        object.__setattr__(self, "T_world_imu", T)
        object.__setattr__(self, "v_world", as_vectors(self.v_world, len(t), "Trajectory.v_world"))
        object.__setattr__(self, "omega_imu", as_vectors(self.omega_imu, len(t), "Trajectory.omega_imu"))

    def __len__(self) -> int:
        return len(self.t)

    def select(self, mask: np.ndarray) -> Trajectory:
        """The states where the boolean ``mask`` (K,) is true."""
        return Trajectory(self.t[mask], self.T_world_imu[mask], self.v_world[mask], self.omega_imu[mask])


@dataclass(frozen=True)
class PathProfile:
    """How far the end effector had travelled at each instant of a recording.

    Attributes:
        t: (K,) int64 [ns] timestamps (IMU clock), strictly increasing.
        length: (K,) [m] end-effector path travelled since the recording started, non-decreasing.
    """

    t: np.ndarray
    length: np.ndarray

    def __post_init__(self) -> None:
        t = as_timestamps(self.t, "PathProfile.t")
        object.__setattr__(self, "t", t)
        length = np.asarray(self.length, dtype=np.float64)
        if length.shape != t.shape or not np.all(np.isfinite(length)) or np.any(np.diff(length) < 0):
            raise DataError(f"PathProfile.length must be {len(t)} finite, non-decreasing path lengths [m]")
        object.__setattr__(self, "length", length)

    def __len__(self) -> int:
        return len(self.t)

    def select(self, mask: np.ndarray) -> PathProfile:
        """The samples where the boolean ``mask`` (K,) is true."""
        return PathProfile(self.t[mask], self.length[mask])

    def time_at(self, path: float) -> int:
        """[ns] the first instant at which the path reaches ``path`` [m] (the last instant if it never does)."""
        k = int(np.searchsorted(self.length, path, side="left"))
        return int(self.t[min(k, len(self.t) - 1)])

    def length_at(self, t_ns: int) -> float:
        """[m] the path travelled by ``t_ns`` (the last profile sample at or before it)."""
        k = int(np.searchsorted(self.t, t_ns, side="right")) - 1
        return float(self.length[k]) if k >= 0 else 0.0

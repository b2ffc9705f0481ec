"""Typed containers for sensor data: IMU samples, camera frames, sensor truth, recordings.

Timestamps are ``int64`` nanoseconds everywhere (float seconds lose ns precision on epoch
times); convert to seconds only relative to a recording's start (``seconds_since``).
Frames follow ``docs/conventions.md``: ``T_a_b`` maps frame-b points into frame a.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vical.data.imu_model import ImuIntrinsics
from vical.data.target import Target
from vical.geometry.camera import CameraModel

NS_PER_S = 1_000_000_000
FIRST_CAMERA = "cam0"
CAMERA_NAME = re.compile(r"cam(\d+)")


class DataError(ValueError):
    """Sensor data whose shape, type or ordering is wrong."""


def seconds_since(t_ns: np.ndarray, t0_ns: int) -> np.ndarray:
    """Float seconds of int64 ns timestamps relative to ``t0_ns`` (exact to ~1e-16 s for short spans)."""
    return (np.asarray(t_ns, dtype=np.int64) - np.int64(t0_ns)).astype(np.float64) / NS_PER_S


def _as_timestamps(t: np.ndarray, name: str) -> np.ndarray:
    t = np.asarray(t)
    if t.ndim != 1:
        raise DataError(f"{name} must be a 1-D array of int64 ns timestamps, got shape {t.shape}")
    if t.size and not np.issubdtype(t.dtype, np.integer):
        raise DataError(f"{name} must hold integer nanoseconds (int64), got dtype {t.dtype}")
    t = t.astype(np.int64)
    if np.any(np.diff(t) <= 0):
        bad = int(np.argmax(np.diff(t) <= 0))
        raise DataError(f"{name} must be strictly increasing; sample {bad + 1} is not after sample {bad}")
    return t


def _as_vectors(x: np.ndarray, n: int, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (n, 3):
        raise DataError(f"{name} must have shape ({n}, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise DataError(f"{name} contains NaN or inf")
    return x


@dataclass(frozen=True)
class ImuNoise:
    """IMU noise model, Kalibr's convention (continuous-time densities).

    A white-noise sample at rate ``rate_hz`` has sigma ``noise_density * sqrt(rate_hz)``;
    the bias moves by a random walk whose increment over ``dt`` has sigma
    ``random_walk * sqrt(dt)``. The defaults are the paper's IMU, the one place its numbers are written: the
    simulator's sensor distribution (``vical.sim.sampling.ImuSampling``, ``conf/sensor/paper.yaml``) defaults to them.

    Attributes:
        accel_noise_density: [m/s^2/sqrt(Hz)]
        accel_random_walk: [m/s^3/sqrt(Hz)]
        gyro_noise_density: [rad/s/sqrt(Hz)]
        gyro_random_walk: [rad/s^2/sqrt(Hz)]
        rate_hz: IMU sample rate [Hz]
    """

    accel_noise_density: float = 0.004
    accel_random_walk: float = 0.006
    gyro_noise_density: float = 0.0003394
    gyro_random_walk: float = 0.000038785
    rate_hz: float = 200.0

    def to_dict(self) -> dict:
        return {k: float(getattr(self, k)) for k in self.__dataclass_fields__}

    @classmethod
    def from_dict(cls, d: dict) -> ImuNoise:
        return cls(**{k: float(v) for k, v in d.items() if k in cls.__dataclass_fields__})

    def scaled(self, factor: float) -> ImuNoise:
        """Every density (white noise and random walk) times ``factor``; the same rate."""
        return ImuNoise(
            self.accel_noise_density * factor,
            self.accel_random_walk * factor,
            self.gyro_noise_density * factor,
            self.gyro_random_walk * factor,
            self.rate_hz,
        )


@dataclass(frozen=True)
class ImuSamples:
    """IMU measurements.

    Attributes:
        t: (N,) int64 [ns] sample timestamps (IMU clock), strictly increasing.
        gyro: (N, 3) [rad/s] angular rate of the IMU frame, in the IMU frame.
        accel: (N, 3) [m/s^2] specific force (acceleration minus gravity) in the IMU frame;
            at rest it reads +9.81 along the IMU-frame direction of world up.
    """

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray

    def __post_init__(self) -> None:
        t = _as_timestamps(self.t, "ImuSamples.t")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "gyro", _as_vectors(self.gyro, len(t), "ImuSamples.gyro"))
        object.__setattr__(self, "accel", _as_vectors(self.accel, len(t), "ImuSamples.accel"))

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def concatenate(cls, parts: list[ImuSamples]) -> ImuSamples:
        """The samples of ``parts`` one after the other (they must follow each other in time)."""
        if not parts:
            return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
        return cls(*(np.concatenate([getattr(p, key) for p in parts]) for key in ("t", "gyro", "accel")))

    def slice_time(self, t0: int, t1: int) -> ImuSamples:
        """Samples with ``t0 <= t <= t1`` [ns]."""
        m = (self.t >= t0) & (self.t <= t1)
        return ImuSamples(self.t[m], self.gyro[m], self.accel[m])


@dataclass(frozen=True)
class CameraFrames:
    """Camera frames with target detections.

    Attributes:
        t: (M,) int64 [ns] frame timestamps (camera clock, see ``SensorTruth.time_offset``).
        corners: M arrays (K_i, 2) float64 [px] detected corner positions (empty when the
            target was not detected in that frame).
        ids: M arrays (K_i,) int64 target point ids of those corners (see ``Target``).
        images: optional (M, H, W) uint8 grey images.
        names: optional M image file names (sources read from files), so that messages can name the
            image a frame came from; None when the frames have no files (bags, simulations).
    """

    t: np.ndarray
    corners: list[np.ndarray]
    ids: list[np.ndarray]
    images: np.ndarray | None = None
    names: list[str] | None = None

    def __post_init__(self) -> None:
        t = _as_timestamps(self.t, "CameraFrames.t")
        object.__setattr__(self, "t", t)
        if len(self.corners) != len(t) or len(self.ids) != len(t):
            raise DataError(
                f"CameraFrames needs one corner and id array per frame: {len(t)} timestamps, "
                f"{len(self.corners)} corner arrays, {len(self.ids)} id arrays"
            )
        corners = [np.asarray(c, dtype=np.float64).reshape(-1, 2) for c in self.corners]
        ids = [np.asarray(i, dtype=np.int64).reshape(-1) for i in self.ids]
        for k, (c, i) in enumerate(zip(corners, ids, strict=True)):
            if len(c) != len(i):
                raise DataError(f"frame {k}: {len(c)} corners but {len(i)} ids")
        object.__setattr__(self, "corners", corners)
        object.__setattr__(self, "ids", ids)
        if self.images is not None:
            images = np.asarray(self.images)
            if images.ndim != 3 or len(images) != len(t) or images.dtype != np.uint8:
                raise DataError(f"images must be (M, H, W) uint8 with M={len(t)}, got {images.shape} {images.dtype}")
            object.__setattr__(self, "images", images)
        if self.names is not None:
            if len(self.names) != len(t):
                raise DataError(f"CameraFrames needs one name per frame: {len(t)} timestamps, {len(self.names)} names")
            object.__setattr__(self, "names", [str(n) for n in self.names])

    def __len__(self) -> int:
        return len(self.t)

    def label(self, k: int) -> str:
        """How messages name frame ``k``: its image file name, else its timestamp [ns]."""
        return self.names[k] if self.names is not None else str(int(self.t[k]))

    @property
    def num_detections(self) -> np.ndarray:
        """(M,) number of detected corners per frame."""
        return np.array([len(i) for i in self.ids], dtype=np.int64)

    def select(self, mask: np.ndarray) -> CameraFrames:
        """Frames where the boolean ``mask`` (M,) is true."""
        idx = np.flatnonzero(mask)
        images = None if self.images is None else self.images[idx]
        names = None if self.names is None else [self.names[i] for i in idx]
        return CameraFrames(self.t[idx], [self.corners[i] for i in idx], [self.ids[i] for i in idx], images, names)


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
    """

    camera: CameraModel
    T_cam_imu: np.ndarray
    time_offset: float = 0.0
    imu_noise: ImuNoise = field(default_factory=ImuNoise)
    gyro_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    accel_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    imu_intrinsics: ImuIntrinsics = field(default_factory=ImuIntrinsics)

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
        )


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
        t = _as_timestamps(self.t, "Trajectory.t")
        object.__setattr__(self, "t", t)
        T = np.asarray(self.T_world_imu, dtype=np.float64)
        if T.shape != (len(t), 4, 4):
            raise DataError(f"Trajectory.T_world_imu must be ({len(t)}, 4, 4), got {T.shape}")
        object.__setattr__(self, "T_world_imu", T)
        object.__setattr__(self, "v_world", _as_vectors(self.v_world, len(t), "Trajectory.v_world"))
        object.__setattr__(self, "omega_imu", _as_vectors(self.omega_imu, len(t), "Trajectory.omega_imu"))

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
        t = _as_timestamps(self.t, "PathProfile.t")
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


@dataclass(frozen=True)
class Recording:
    """Everything one data collection produced.

    Attributes:
        imu: IMU samples.
        frames: camera frames with detections.
        target: the calibration target.
        truth: the sensor's true parameters (simulation) or None (real data).
        trajectory: ground-truth IMU trajectory or None.
        T_world_target: (4, 4) target pose in the world frame, or None when unknown.
        path_length: [m] end-effector path length of the motion (0 when unknown).
        duration: [s] duration of the motion (0 when unknown).
        metadata: free-form YAML-serialisable information (seed, config, source).
        path_profile: the end effector's path over time (None when unknown); needed to cut the
            recording at a path budget (``until_path``).
        other_frames: the frames of a rig's other cameras, by Kalibr name (``cam1``, ``cam2``, ...;
            ``frames`` are ``cam0``'s), each on its own clock and at its own rate.
        other_truths: those cameras' true parameters (their ``T_cam_imu`` and ``time_offset``
            relative to the same IMU), by name; empty for real data.
    """

    imu: ImuSamples
    frames: CameraFrames
    target: Target
    truth: SensorTruth | None = None
    trajectory: Trajectory | None = None
    T_world_target: np.ndarray | None = None
    path_length: float = 0.0
    duration: float = 0.0
    metadata: dict[str, Any] = field(default_factory=dict)
    path_profile: PathProfile | None = None
    other_frames: dict[str, CameraFrames] = field(default_factory=dict)
    other_truths: dict[str, SensorTruth] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = list(self.other_frames)
        numbers = sorted(int(m.group(1)) for n in names if (m := CAMERA_NAME.fullmatch(n)))
        if len(numbers) != len(names) or numbers != list(range(1, len(names) + 1)):
            raise DataError(
                f"a rig's other cameras are named cam1, cam2, ... without gaps (cam0 is frames), got {names}"
            )
        object.__setattr__(self, "other_frames", {f"cam{n}": self.other_frames[f"cam{n}"] for n in numbers})
        unknown = sorted(set(self.other_truths) - set(names))
        if unknown:
            raise DataError(f"other_truths names {unknown[0]}, which has no frames (cameras: {self.camera_names})")

    @property
    def camera_names(self) -> list[str]:
        """``cam0`` (``frames``), then the other cameras in order."""
        return [FIRST_CAMERA, *self.other_frames]

    def frames_of(self, name: str) -> CameraFrames:
        """The frames of camera ``name``; a ``DataError`` names the cameras the recording has."""
        if name == FIRST_CAMERA:
            return self.frames
        if name not in self.other_frames:
            raise DataError(f"the recording has no camera {name!r}; it has {self.camera_names}")
        return self.other_frames[name]

    def truth_of(self, name: str) -> SensorTruth | None:
        """The true parameters of camera ``name`` (None when unknown)."""
        self.frames_of(name)
        return self.truth if name == FIRST_CAMERA else self.other_truths.get(name)

    @property
    def t0(self) -> int:
        """Earliest timestamp [ns] of the recording (reference for relative seconds)."""
        starts = [int(x.t[0]) for x in (self.imu, self.frames, *self.other_frames.values()) if len(x)]
        if not starts:
            raise DataError("recording holds neither IMU samples nor camera frames")
        return min(starts)

    @property
    def t_end(self) -> int:
        """Latest timestamp [ns] of the recording."""
        ends = [int(x.t[-1]) for x in (self.imu, self.frames, *self.other_frames.values()) if len(x)]
        if not ends:
            raise DataError("recording holds neither IMU samples nor camera frames")
        return max(ends)

    def until(self, t_end_ns: int) -> Recording:
        """The recording as it stood at ``t_end_ns``: every sample, frame (by its stamp) and truth state up to it.

        ``path_length`` becomes the path travelled by then (when the profile is known) and
        ``duration`` the time since the recording's start.
        """
        t_end, profile = int(t_end_ns), self.path_profile
        return replace(
            self._stamped_between(np.iinfo(np.int64).min, t_end),
            path_length=self.path_length if profile is None else profile.length_at(t_end),
            duration=min(self.duration, (t_end - self.t0) / NS_PER_S),
        )

    def window(self, t_start_ns: int, t_end_ns: int) -> Recording:
        """The part of the recording stamped ``t_start_ns <= t <= t_end_ns``: samples, every camera's frames, truth
        states; ``path_length`` and ``duration`` those of the window."""
        t0, t1, profile = int(t_start_ns), int(t_end_ns), self.path_profile
        return replace(
            self._stamped_between(t0, t1),
            path_length=self.path_length if profile is None else profile.length_at(t1) - profile.length_at(t0),
            duration=(min(t1, self.t_end) - max(t0, self.t0)) / NS_PER_S,
        )

    def _stamped_between(self, t0: int, t1: int) -> Recording:
        """The samples, every camera's frames and the truth states stamped ``t0 <= t <= t1`` [ns]; the rest as is."""
        trajectory, profile = self.trajectory, self.path_profile

        def inside(t: np.ndarray) -> np.ndarray:
            return (t >= t0) & (t <= t1)

        return replace(
            self,
            imu=self.imu.slice_time(t0, t1),
            frames=self.frames.select(inside(self.frames.t)),
            other_frames={name: f.select(inside(f.t)) for name, f in self.other_frames.items()},
            trajectory=None if trajectory is None else trajectory.select(inside(trajectory.t)),
            path_profile=None if profile is None else profile.select(inside(profile.t)),
        )

    def until_path(self, budget_m: float) -> Recording:
        """The recording up to the instant the end effector's path reached ``budget_m`` [m] (``until``).

        The whole recording when its path stays below the budget. Raises ``DataError`` when the
        recording has no path profile.
        """
        if self.path_profile is None or not len(self.path_profile):
            raise DataError("this recording has no path profile (path over time); it cannot be cut at a path budget")
        if budget_m >= self.path_profile.length[-1]:
            return self
        return self.until(self.path_profile.time_at(budget_m))

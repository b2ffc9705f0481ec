"""Everything one data collection produced (``Recording``): IMU samples, camera frames, target, truth."""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vical.data.camera_frames import CameraFrames
from vical.data.errors import DataError
from vical.data.imu import ImuSamples
from vical.data.sample_arrays import NS_PER_S
from vical.data.sensor_truth import SensorTruth
from vical.data.target import Target
from vical.data.trajectory import PathProfile, Trajectory

FIRST_CAMERA = "cam0"
CAMERA_NAME = re.compile(r"cam(\d+)")


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

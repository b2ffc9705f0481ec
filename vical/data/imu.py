"""IMU measurements (``ImuSamples``) and the IMU noise model (``ImuNoise``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vical.data.sample_arrays import as_timestamps, as_vectors


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
        t = as_timestamps(self.t, "ImuSamples.t")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "gyro", as_vectors(self.gyro, len(t), "ImuSamples.gyro"))
        object.__setattr__(self, "accel", as_vectors(self.accel, len(t), "ImuSamples.accel"))

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

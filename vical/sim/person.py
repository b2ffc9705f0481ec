"""A simulated person holding the sensor: how a hand follows a suggested pose, with error, lag and tremor.

``vical-guide`` shows a person where to hold the sensor next; to develop and compare guidance without a person,
``SimulatedPerson`` moves the sensor as a hand would. One model for every comparison (``HandModel``):

- **placement error**: each suggestion is reached only approximately: the pose the hand settles at is the
  suggested one moved by a normal error, 4 cm per axis (a 3-D rms of 6.9 cm, "7 cm") and 5.77 deg per rotation
  axis (an rms angle of 10 deg), in the suggested pose's own frame;
- **lag**: a reach starts when the last one has settled (a person finishes one placement before reading the
  next instruction) and follows the minimum-jerk profile (``vical.sim.motion.quintic``, the shape of human
  point-to-point reaching) over at least ``settle_s`` (1.5 s); a longer reach is slowed so that its peak speed
  stays within ``max_speed`` (0.5 m/s) and its peak rate within ``max_rate`` (90 deg/s), as a person walking the
  sensor across the room would;
- **tremor**: physiological tremor on top of everything, 1 mm and 0.3 deg rms per axis, in the 8-12 Hz band:
  per axis a sum of ``TREMOR_COMPONENTS`` sinusoids of frequencies drawn uniformly in the band and random
  phases, their amplitudes set so that the time-averaged rms is exactly the model's; smooth, so that an IMU on
  the sensor reads its accelerations and rates.

Poses are ``T_world_sensor`` (4, 4) of the hand-held body, translation interpolated linearly and rotation along
the geodesic, both by the same profile; the tremor's rotation is applied in the body frame, its translation in
the world frame. Everything is drawn from the generator given to the person, so a seed gives one person.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from vical.config_checks import require, require_range
from vical.sim.motion import QUINTIC_PEAK_VELOCITY, quintic

TREMOR_COMPONENTS = 8  # sinusoids per axis: a band-limited, non-periodic tremor over minutes


def reach_duration(distance: float, angle: float, min_s: float, max_speed: float, max_rate: float) -> float:
    """[s] a minimum-jerk reach over ``distance`` [m] and ``angle`` [rad]: at least ``min_s``, slowed so that its peak
    speed stays within ``max_speed`` [m/s] and its peak rate within ``max_rate`` [deg/s]."""
    return max(
        min_s, QUINTIC_PEAK_VELOCITY * distance / max_speed, QUINTIC_PEAK_VELOCITY * angle / np.radians(max_rate)
    )


@dataclass(frozen=True)
class HandModel:
    """How the simulated person follows a suggestion (module doc).

    Attributes:
        placement_sigma_m: [m] standard deviation per axis of where the hand settles against the suggestion.
        placement_sigma_deg: [deg] standard deviation per rotation axis of the orientation it settles at.
        settle_s: [s] the shortest reach (minimum-jerk, from rest to rest).
        max_speed: [m/s] the peak speed of a reach; max_rate: [deg/s] its peak rotation rate.
        tremor_m: [m] rms per axis of the tremor's translation; tremor_deg: [deg] rms per axis of its rotation.
        tremor_band_hz: (low, high) [Hz] the tremor's frequency band.
    """

    placement_sigma_m: float = 0.04
    placement_sigma_deg: float = 10.0 / np.sqrt(3.0)
    settle_s: float = 1.5
    max_speed: float = 0.5
    max_rate: float = 90.0
    tremor_m: float = 0.001
    tremor_deg: float = 0.3
    tremor_band_hz: tuple[float, float] = (8.0, 12.0)

    def __post_init__(self) -> None:
        for name in ("placement_sigma_m", "placement_sigma_deg", "tremor_m", "tremor_deg"):
            require_range(f"person.{name}", getattr(self, name), 0.0)
        for name in ("settle_s", "max_speed", "max_rate"):
            require_range(f"person.{name}", getattr(self, name), 0.0, low_open=True)
        band = tuple(self.tremor_band_hz)
        ok = len(band) == 2 and all(isinstance(f, int | float) for f in band) and 0 < band[0] <= band[1] < np.inf
        require(ok, "person.tremor_band_hz", "[low, high] with 0 < low <= high [Hz]", self.tremor_band_hz)
        object.__setattr__(self, "tremor_band_hz", (float(band[0]), float(band[1])))


@dataclass(frozen=True)
class Reach:
    """One reach of the hand: from ``start`` (4, 4) at rest at ``t0`` [s] to ``end`` (4, 4), at rest ``duration``
    [s] later (without the tremor)."""

    t0: float
    duration: float
    start: np.ndarray
    end: np.ndarray

    @property
    def t_end(self) -> float:
        return self.t0 + self.duration

    def poses(self, t: np.ndarray) -> np.ndarray:
        """(N, 4, 4) the reach's poses at times ``t`` (N,) [s]: at ``start`` before it, at ``end`` after it."""
        s = quintic((np.asarray(t, dtype=float) - self.t0) / self.duration)[0]
        turn = Rotation.from_matrix(self.start[:3, :3].T @ self.end[:3, :3]).as_rotvec()
        T = np.tile(np.eye(4), (len(s), 1, 1))
        T[:, :3, :3] = self.start[:3, :3] @ Rotation.from_rotvec(s[:, None] * turn).as_matrix()
        T[:, :3, 3] = self.start[:3, 3] + s[:, None] * (self.end[:3, 3] - self.start[:3, 3])
        return T


@dataclass(frozen=True)
class Tremor:
    """The tremor of one person: per axis (x, y, z, then rotation about x, y, z) ``TREMOR_COMPONENTS`` sinusoids.

    Attributes:
        frequencies, phases, amplitudes: (6, K) [Hz], [rad], [m] or [rad].
    """

    frequencies: np.ndarray
    phases: np.ndarray
    amplitudes: np.ndarray

    @classmethod
    def draw(cls, model: HandModel, rng: np.random.Generator) -> Tremor:
        """Frequencies uniform in the band, random phases, amplitudes giving the model's rms exactly (a sum of
        ``K`` sinusoids of distinct frequencies and amplitude ``a`` has the time-averaged rms ``a sqrt(K / 2)``)."""
        k = TREMOR_COMPONENTS
        frequencies = rng.uniform(*model.tremor_band_hz, (6, k))
        phases = rng.uniform(0.0, 2.0 * np.pi, (6, k))
        rms = np.r_[np.full(3, model.tremor_m), np.full(3, np.radians(model.tremor_deg))]
        return cls(frequencies, phases, np.repeat((rms * np.sqrt(2.0 / k))[:, None], k, axis=1))

    def offsets(self, t: np.ndarray) -> np.ndarray:
        """(N, 6) the tremor's translation [m] and rotation vector [rad] at times ``t`` (N,) [s]."""
        arg = 2.0 * np.pi * self.frequencies[None] * np.asarray(t, dtype=float)[:, None, None] + self.phases[None]
        return np.sum(self.amplitudes[None] * np.sin(arg), axis=2)


@dataclass
class SimulatedPerson:
    """A person holding the sensor at ``start`` (4, 4) from time 0, following suggestions (module doc).

    Args:
        start: ``T_world_sensor`` where the person holds it at first.
        rng: draws the person's tremor now and each placement's error as it is asked.
        model: how the hand follows.
    """

    start: np.ndarray
    rng: np.random.Generator
    model: HandModel = field(default_factory=HandModel)
    reaches: list[Reach] = field(default_factory=list, init=False)

    def __post_init__(self) -> None:
        self.start = np.asarray(self.start, dtype=float)
        self.tremor = Tremor.draw(self.model, self.rng)

    @property
    def settled_at(self) -> float:
        """[s] when the hand has settled after its last reach (0 before the first)."""
        return self.reaches[-1].t_end if self.reaches else 0.0

    @property
    def rest_pose(self) -> np.ndarray:
        """(4, 4) where the hand rests after its last reach (without the tremor)."""
        return self.reaches[-1].end if self.reaches else self.start

    def follow(self, suggested: np.ndarray, t: float) -> Reach:
        """Follow the suggestion ``T_world_sensor`` (4, 4) given at time ``t`` [s]: a reach from the rest pose to
        the suggestion moved by this placement's error, starting when the last reach has settled (or at ``t``)."""
        suggested = np.asarray(suggested, dtype=float)
        m = self.model
        error = np.eye(4)
        error[:3, :3] = Rotation.from_rotvec(self.rng.normal(0.0, np.radians(m.placement_sigma_deg), 3)).as_matrix()
        error[:3, 3] = self.rng.normal(0.0, m.placement_sigma_m, 3)
        start, end = self.rest_pose, suggested @ error
        reach = Reach(max(float(t), self.settled_at), self._duration(start, end), start, end)
        self.reaches.append(reach)
        return reach

    def _duration(self, start: np.ndarray, end: np.ndarray) -> float:
        """[s] the reach's duration: at least ``settle_s``, slowed so that its peak speed and rate stay in bounds."""
        distance = float(np.linalg.norm(end[:3, 3] - start[:3, 3]))
        angle = float(np.linalg.norm(Rotation.from_matrix(start[:3, :3].T @ end[:3, :3]).as_rotvec()))
        m = self.model
        return reach_duration(distance, angle, m.settle_s, m.max_speed, m.max_rate)

    def poses(self, t: np.ndarray) -> np.ndarray:
        """(N, 4, 4) ``T_world_sensor`` at times ``t`` (N,) [s], tremor included: each time on the reach it falls in
        (or the rest before the next one)."""
        t = np.asarray(t, dtype=float)
        T = np.tile(self.start, (len(t), 1, 1))
        for reach in self.reaches:  # each reach holds from its start on, until a later one starts
            on = t >= reach.t0
            if on.any():
                T[on] = reach.poses(t[on])
        shake = self.tremor.offsets(t)
        T[:, :3, :3] = T[:, :3, :3] @ Rotation.from_rotvec(shake[:, 3:]).as_matrix()
        T[:, :3, 3] += shake[:, :3]
        return T

"""IMU simulation: physics readings at the physics rate -> IMU samples at the IMU rate + noise.

``ImuSiteReader`` gives the ideal specific force and angular rate of the IMU site at every physics
step (central differences of the site's executed poses; see its docstring for why not MuJoCo's
``accelerometer`` and ``gyro`` sensors). An IMU sample at time ``t`` is either the
reading at ``t`` (``instant``) or the mean of the readings over the sample interval centred on
``t`` (``average``, a real IMU's anti-aliasing: what moves faster than the IMU rate is averaged
out instead of folding into the samples; centring keeps the samples free of a group delay, which
would otherwise masquerade as a camera-IMU time offset). ``docs/sensors.md`` has the measured
effect of the choice.

Intrinsics (``vical.data.ImuIntrinsics``, Kalibr's ``scale-misalignment``): the ideal readings are
first scaled, misaligned and (gyro) made sensitive to specific force, ``M_a a`` and
``M_g C w + A C a``.

Noise (Kalibr's model, ``vical.data.ImuNoise``): per axis, the measurement is
``truth + bias_k + n_k`` with white ``n_k ~ N(0, density^2 * rate)`` and a bias random walk
``bias_{k+1} = bias_k + w_k``, ``w_k ~ N(0, random_walk^2 / rate)``; ``bias_0`` is the sensor's
initial bias.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

import mujoco
import numpy as np

from vical.data import ImuIntrinsics, ImuNoise, ImuSamples, SensorTruth
from vical.sim.sampling import IMU_SAMPLING


class ImuSimulationError(RuntimeError):
    """IMU readings that do not arrive at every physics step."""


class SiteReadings(NamedTuple):
    """Ideal IMU readings and ground-truth states of a site at consecutive physics steps.

    Attributes:
        t_ns: (N,) int64 times of the physics states [ns].
        reading: (N, 6) ``[gyro (3) rad/s, specific force (3) m/s^2]`` in the site frame.
        p_world: (N, 3) [m] site positions; R_world_site: (N, 3, 3) site orientations.
        v_world: (N, 3) [m/s] site velocities, world axes.
        omega_site: (N, 3) [rad/s] site angular velocities, site axes (= the gyro readings).
    """

    t_ns: np.ndarray
    reading: np.ndarray
    p_world: np.ndarray
    R_world_site: np.ndarray
    v_world: np.ndarray
    omega_site: np.ndarray


class ImuSiteReader:
    """Ideal IMU readings of a site: the angular rate and specific force of the executed motion.

    A reading at physics step ``k`` comes from the site poses of steps ``k - 1``, ``k``, ``k + 1``
    by central differences: angular rate ``vee(R_k^T (R_{k+1} - R_{k-1})) / 2h`` (the antisymmetric
    part, scaled by ``angle / sin(angle)`` of the step's rotation to second order: then it equals
    ``(log(R_k^T R_{k+1}) - log(R_k^T R_{k-1})) / 2h`` to ~1e-12 relative) and specific force
    ``R_k^T ((p_{k+1} - 2 p_k + p_{k-1}) / h^2 - g)``.
    These are exact (to O(h^2)) for the pose trajectory that the camera observes, so the two
    sensors agree in time.

    Why not MuJoCo's ``gyro`` and ``accelerometer`` sensors, which sit on the same site: its
    integrators are semi-implicit (``q_{k+1} = q_k + h v_{k+1}``), so the velocity ``v_k`` that the
    sensors read belongs to the step before ``t_k``, half a step earlier than the pose ``q_k``;
    with ``implicitfast`` the accelerometer also uses the forward-pass acceleration, not the one
    the implicitly damped actuators produce. Measured on the Panda scene: the raw accelerometer
    was off by up to 0.1 m/s^2 during motions, and the half-step lead of the gyro made the
    calibrator find a 0.46 ms camera-IMU time offset on recordings simulated with none. The
    sensors stay in the scene as a cross-check (``tests/test_sim_imu.py``) and read the same
    values at rest.

    ``record_steps`` keeps the site poses of a motion's physics steps (``record``: of one step);
    ``readings`` differences the poses kept since its last call in one vectorised pass. The per-row
    products go through the same BLAS kernels as a step-by-step evaluation, so the readings are the
    same floats however often ``readings`` is called.
    """

    def __init__(self, model: mujoco.MjModel, site: str = "imu"):
        self.model = model
        self._site = model.site(site).id
        self._gravity = np.array(model.opt.gravity, dtype=float)
        self._p: list[np.ndarray] = []  # site positions (K_i, 3) of consecutive steps, the first at _t0_ns
        self._R: list[np.ndarray] = []  # site orientations, row-major (K_i, 9)
        self._t0_ns = 0
        self._step_ns = 0
        self._t_ns: int | None = None  # time of the next physics step to record

    def reset(self, t_ns: int) -> None:
        """Start over: the next ``record`` (which brings the pose of ``t_ns`` itself) must be that of the
        physics step starting at ``t_ns``."""
        self._p, self._R = [], []
        self._t0_ns = int(t_ns)
        self._t_ns = int(t_ns)

    def record(self, data: mujoco.MjData, t_ns: int, step_ns: int) -> None:
        """Keep the site pose of the physics step starting at ``t_ns``.

        Call right after the ``mj_step`` that started at ``t_ns`` (``data``'s kinematics are those
        of ``t_ns``); every physics step must be recorded.
        """
        self.record_steps(t_ns, step_ns, data.site_xpos[self._site][None], data.site_xmat[self._site][None])

    def record_steps(self, t0_ns: int, step_ns: int, p: np.ndarray, R: np.ndarray) -> None:
        """Keep the site poses ``p`` (K, 3) [m], ``R`` (K, 9) (row-major) of the K physics steps from ``t0_ns``.

        Every physics step must be recorded, in order.
        """
        self.check_next(t0_ns)
        self._t_ns = t0_ns + len(p) * step_ns
        self._step_ns = step_ns
        self._p.append(np.array(p, dtype=float).reshape(-1, 3))
        self._R.append(np.array(R, dtype=float).reshape(-1, 9))

    def check_next(self, t_ns: int) -> None:
        """Raise ``ImuSimulationError`` unless the next step to record is the one starting at ``t_ns``."""
        if self._t_ns != t_ns:
            if self._t_ns is None:
                raise ImuSimulationError("IMU reader got a physics step before reset(t_ns) (SensorRecorder.start)")
            raise ImuSimulationError(
                f"IMU reader expected the physics step starting at {self._t_ns} ns, got {t_ns} ns; "
                "every physics step must be reported (reset the reader after moving without it)"
            )

    def readings(self) -> SiteReadings:
        """The readings of every recorded step whose next step is recorded too, since the last call.

        A reading needs the steps before and after it: the first recorded step never has one, and
        the last one waits for the next ``record``.
        """
        p = np.concatenate(self._p) if self._p else np.zeros((0, 3))
        n = len(p)
        if n < 3:
            empty = np.zeros((0, 3))
            return SiteReadings(np.zeros(0, dtype=np.int64), np.zeros((0, 6)), empty, np.zeros((0, 3, 3)), empty, empty)
        h_ns = self._step_ns
        t_ns = self._t0_ns + h_ns * np.arange(1, n - 1, dtype=np.int64)
        R = np.concatenate(self._R).reshape(-1, 3, 3)
        self._p, self._R = [p[-2:]], [R[-2:].reshape(-1, 9)]  # the next reading's previous and own pose
        self._t0_ns += (n - 2) * h_ns
        return self._central_difference(t_ns, p, R, h_ns * 1e-9)

    def _central_difference(self, t_ns: np.ndarray, p: np.ndarray, R: np.ndarray, h: float) -> SiteReadings:
        """Readings at the inner rows of the poses ``p`` (M, 3), ``R`` (M, 3, 3) (M - 2 of them)."""
        p_m, p_0, p_p = p[:-2], p[1:-1], p[2:]
        R_m, R_0, R_p = R[:-2], R[1:-1], R[2:]
        M = np.swapaxes(R_0, 1, 2) @ (R_p - R_m)
        omega = np.stack([M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0], M[:, 1, 0] - M[:, 0, 1]], axis=1)
        omega *= 0.25 / h
        # The antisymmetric part holds sin(angle) per step: angle / sin(angle) ~ 1 + angle^2 / 6.
        omega *= (1.0 + row_dot(omega, omega) * (h * h) / 6.0)[:, None]
        accel_world = (p_p - 2.0 * p_0 + p_m) * (1.0 / (h * h))
        specific_force = ((accel_world - self._gravity)[:, None, :] @ R_0)[:, 0, :]
        reading = np.concatenate([omega, specific_force], axis=1)
        return SiteReadings(t_ns, reading, p_0, R_0, (p_p - p_m) * (0.5 / h), omega)


def row_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) dot products of the rows of ``a`` and ``b`` (N, 3), as ``a[i] @ b[i]`` computes each."""
    return (a[:, None, :] @ b[:, :, None])[:, 0, 0]


def window_weights(steps_per_sample: int, sampling: str) -> tuple[np.ndarray, np.ndarray]:
    """Physics-step offsets and weights that turn readings into one IMU sample.

    Args:
        steps_per_sample: physics steps per IMU period ``n``.
        sampling: ``instant`` (offset 0, weight 1) or ``average`` (the mean over
            ``[t - n/2, t + n/2]`` steps: midpoint rule for odd ``n``, trapezoid rule for even ``n``).

    Returns:
        offsets (L,) int [steps] relative to the sample instant, weights (L,) summing to 1.
    """
    if sampling not in IMU_SAMPLING:
        raise ValueError(f"IMU sampling must be one of {IMU_SAMPLING}, got {sampling!r}")
    n = int(steps_per_sample)
    if n < 1:
        raise ValueError(f"steps_per_sample must be >= 1, got {n}")
    if sampling == "instant" or n == 1:
        return np.zeros(1, dtype=np.int64), np.ones(1)
    if n % 2:
        half = (n - 1) // 2
        return np.arange(-half, half + 1), np.full(n, 1.0 / n)
    weights = np.full(n + 1, 1.0 / n)
    weights[[0, -1]] = 0.5 / n
    return np.arange(-n // 2, n // 2 + 1), weights


def discrete_sigmas(noise: ImuNoise) -> dict[str, float]:
    """Per-sample sigmas of Kalibr's densities at ``noise.rate_hz``.

    Returns ``accel_white`` [m/s^2], ``gyro_white`` [rad/s] (density * sqrt(rate)) and
    ``accel_walk`` [m/s^2], ``gyro_walk`` [rad/s] (bias increment per sample: random_walk / sqrt(rate)).
    """
    root = float(np.sqrt(noise.rate_hz))
    return {
        "accel_white": noise.accel_noise_density * root,
        "gyro_white": noise.gyro_noise_density * root,
        "accel_walk": noise.accel_random_walk / root,
        "gyro_walk": noise.gyro_random_walk / root,
    }


class ImuNoiseProcess:
    """White noise + bias random walk, applied chunk by chunk with the bias carried over.

    The generator is drawn in sample order, 12 normals per sample, so the noise of a sample does
    not depend on how the stream is split into chunks.
    """

    def __init__(
        self, noise: ImuNoise, rng: np.random.Generator, gyro_bias: np.ndarray, accel_bias: np.ndarray
    ) -> None:
        sig = discrete_sigmas(noise)
        self._white = np.array([sig["gyro_white"]] * 3 + [sig["accel_white"]] * 3)
        self._walk = np.array([sig["gyro_walk"]] * 3 + [sig["accel_walk"]] * 3)
        self._rng = rng
        self._bias = np.concatenate([np.asarray(gyro_bias, float), np.asarray(accel_bias, float)])

    def apply(self, gyro: np.ndarray, accel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Noisy gyro (N, 3) [rad/s] and accel (N, 3) [m/s^2] of ideal ones, and the biases (N, 6) used."""
        n = len(gyro)
        draws = self._rng.standard_normal((n, 12))
        increments = draws[:, 6:] * self._walk
        # Sample k carries the bias before increment k (bias_0 is the initial bias). Summing
        # sequentially from the carried bias gives the same floats however the stream is chunked.
        walk = np.cumsum(np.vstack([self._bias, increments]), axis=0)
        biases, self._bias = walk[:-1], walk[-1]
        noisy = np.hstack([gyro, accel]) + biases + draws[:, :6] * self._white
        return noisy[:, :3], noisy[:, 3:], biases


class ImuSimulator:
    """Turns physics-step readings into noisy IMU samples (streaming).

    Args:
        step_ns: physics step [ns].
        steps_per_sample: physics steps per IMU period (``vical.sim.PhysicsConfig.steps_per_period``).
        sampling: ``average`` or ``instant`` (see the module docstring).
        noise: Kalibr noise model (None: noise-free, bias-free samples).
        rng: generator for the noise (needed when ``noise`` is given).
        gyro_bias, accel_bias: (3,) initial biases [rad/s], [m/s^2].
        intrinsics: the IMU's scale, misalignment and g-sensitivity (None: exact axes).

    Samples fall on multiples of the IMU period in the physics clock; a sample is complete once
    every reading of its window has arrived. Noise is drawn in sample order when samples are
    requested, so it does not depend on how often they are.
    """

    def __init__(
        self,
        step_ns: int,
        steps_per_sample: int,
        sampling: str = "average",
        noise: ImuNoise | None = None,
        rng: np.random.Generator | None = None,
        gyro_bias: np.ndarray | None = None,
        accel_bias: np.ndarray | None = None,
        intrinsics: ImuIntrinsics | None = None,
    ) -> None:
        self.step_ns = int(step_ns)
        self._intrinsics = intrinsics
        self.period_steps = int(steps_per_sample)
        offsets, self._weights = window_weights(steps_per_sample, sampling)
        self._first_offset, self._last_offset = int(offsets[0]), int(offsets[-1])
        if noise is not None and rng is None:
            raise ValueError("ImuSimulator needs a seeded numpy Generator to draw IMU noise")
        self._noise = None
        if noise is not None:
            zero = np.zeros(3)
            gyro_bias = zero if gyro_bias is None else gyro_bias
            accel_bias = zero if accel_bias is None else accel_bias
            self._noise = ImuNoiseProcess(noise, rng, gyro_bias, accel_bias)
        # Readings (6,) [gyro, accel] of consecutive physics steps, row 0 = step ``_base_step``;
        # rows before the next sample's window are dropped after each sample.
        self._buffer = np.zeros((len(offsets) + self.period_steps, 6))
        self._count = 0
        self._base_step: int | None = None
        self._next_step = 0  # physics step of the next sample instant
        self._ideal_t: list[int] = []
        self._ideal: list[np.ndarray] = []
        self._t = np.zeros(0, dtype=np.int64)
        self._gyro = np.zeros((0, 3))
        self._accel = np.zeros((0, 3))

    def add_readings(self, t_ns: int, readings: np.ndarray) -> None:
        """Record the ideal ``[gyro (3) rad/s, accel (3) m/s^2]`` (N, 6) of N consecutive physics states,
        the first at ``t_ns``."""
        readings = np.asarray(readings, dtype=float).reshape(-1, 6)
        if not len(readings):
            return
        step, rem = divmod(int(t_ns), self.step_ns)
        if rem:
            raise ImuSimulationError(f"IMU reading at t = {t_ns} ns is not on the physics grid ({self.step_ns} ns)")
        if self._base_step is None:
            self._base_step = step
            first_center = step - self._first_offset
            self._next_step = -(-first_center // self.period_steps) * self.period_steps
        elif step != self._base_step + self._count:
            expected = (self._base_step + self._count) * self.step_ns
            raise ImuSimulationError(
                f"IMU readings must arrive at every physics step: expected t = {expected} ns, got {t_ns} ns"
            )
        end = self._count + len(readings)
        if end > len(self._buffer):
            self._buffer = np.vstack([self._buffer[: self._count], np.zeros((end, 6))])
        self._buffer[self._count : end] = readings
        self._count = end
        self._emit_complete()

    def _emit_complete(self) -> None:
        """Turn every sample whose window has fully arrived into an ideal sample; drop the rows no later
        sample needs."""
        last_step = self._base_step + self._count - 1
        centres = np.arange(self._next_step, last_step - self._last_offset + 1, self.period_steps)
        if len(centres):
            rows = (centres + self._first_offset - self._base_step)[:, None] + np.arange(len(self._weights))
            # (1, L) @ (L, 6) per sample: the same BLAS product as one sample at a time.
            ideal = (self._weights[None, None, :] @ self._buffer[rows])[:, 0, :]
            self._ideal.extend(ideal)
            self._ideal_t.extend((centres * self.step_ns).tolist())
            self._next_step = int(centres[-1]) + self.period_steps
        drop = min(self._next_step + self._first_offset - self._base_step, self._count)
        keep = self._count - drop
        self._buffer[:keep] = self._buffer[drop : self._count]
        self._count = keep
        self._base_step += drop

    def samples(self) -> ImuSamples:
        """All complete IMU samples so far."""
        if self._ideal:
            ideal = np.asarray(self._ideal)
            gyro, accel = ideal[:, :3], ideal[:, 3:]
            if self._intrinsics is not None:
                gyro, accel = self._intrinsics.distort(gyro, accel)
            if self._noise is not None:
                gyro, accel, _ = self._noise.apply(gyro, accel)
            self._t = np.concatenate([self._t, np.asarray(self._ideal_t, dtype=np.int64)])
            self._gyro = np.vstack([self._gyro, gyro])
            self._accel = np.vstack([self._accel, accel])
            self._ideal, self._ideal_t = [], []
        return ImuSamples(self._t.copy(), self._gyro.copy(), self._accel.copy())


STATIC_GRAVITY = 9.81  # [m/s^2] the specific force of an IMU at rest (MuJoCo's gravity, the simulated arm's)
STATIC_CHUNK_S = 60.0  # [s] of samples generated at a time: hours of data in bounded memory


def static_imu(truth: SensorTruth, rng: np.random.Generator, duration_s: float) -> Iterator[ImuSamples]:
    """The IMU of ``truth`` lying still, z axis up, for ``duration_s``, in chunks of ``STATIC_CHUNK_S``.

    Closed form: the true rates are zero and the specific force is gravity along +z; the readings go
    through the IMU's intrinsics (``ImuIntrinsics.distort``) and its noise (``ImuNoiseProcess``: white noise
    and bias random walk from the initial biases, drawn in sample order, so the data do not depend on the
    chunking). The earth's rotation (7.3e-5 rad/s) is left out, as a bias it would hide in the gyro's.
    Stamps [ns] start at 0, one IMU period apart.
    """
    noise = truth.imu_noise
    period_ns = round(1e9 / noise.rate_hz)
    total = round(duration_s * noise.rate_hz)
    gyro, accel = truth.imu_intrinsics.distort(np.zeros((1, 3)), np.array([[0.0, 0.0, STATIC_GRAVITY]]))
    process = ImuNoiseProcess(noise, rng, truth.gyro_bias, truth.accel_bias)
    per_chunk = max(1, round(STATIC_CHUNK_S * noise.rate_hz))
    for start in range(0, total, per_chunk):
        n = min(per_chunk, total - start)
        noisy_gyro, noisy_accel, _ = process.apply(np.repeat(gyro, n, axis=0), np.repeat(accel, n, axis=0))
        yield ImuSamples((start + np.arange(n, dtype=np.int64)) * period_ns, noisy_gyro, noisy_accel)

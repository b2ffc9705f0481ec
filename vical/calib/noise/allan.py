"""IMU noise from a static recording: Allan deviation per axis and Kalibr's noise parameters read from it.

Per axis, the overlapping Allan deviation ``sigma(tau)`` of the readings (``allantools.oadev``) is
fitted with three terms of the power-law model of IEEE Std 952-1997 (Annex C): a least-squares fit of
the Allan variance with non-negative coefficients, each point weighted by the clusters behind it::

    sigma^2(tau) = N^2 / tau  +  (0.664 B)^2  +  K^2 tau / 3
                   white noise   flat floor      bias random walk

and read as the Allan-plot lines are read:

- noise density ``N`` [unit/sqrt(Hz)]: the slope -1/2 line ``N / sqrt(tau)``, read at tau = 1 s;
- random walk ``K`` [unit/s/sqrt(Hz)]: the slope +1/2 line ``K sqrt(tau / 3)``, read at tau = 3 s;
- bias instability ``B`` [unit]: the flat minimum of the fitted curve divided by 0.664
  (``sqrt(2 ln 2 / pi)``, the level of flicker noise's floor). The measured curve's own minimum is
  biased low by its noise (simulated flicker: -13 to -36 %), the fitted one's was within 4 %.

Fitting the terms together keeps each line free of the others' share near the curve's minimum,
which reading single points of the curve does not; the floor enters the fit only where the curve
shows one (``fit_terms``). The unit is rad/s for the gyro and m/s^2 for the accelerometer: ``N`` in
rad/s/sqrt(Hz) or m/s^2/sqrt(Hz), ``K`` in rad/s^2/sqrt(Hz) or m/s^3/sqrt(Hz), Kalibr's units.

The quantization (slope -1) and rate-ramp (slope +1) terms of the standard's five are left out: on
simulated white noise + random walk they took a share of the random walk (-10 % on average over 90
one-hour streams, against -2.6 % without them), and a MEMS IMU's curve rarely shows them at the
averaging times read here.

Deviations come from ``MIN_CLUSTERS`` non-overlapping clusters or more (``tau <= T / 10``) and the
fit starts at ``FIT_MIN_SAMPLES`` samples per cluster, where an IMU's anti-aliasing filter no longer
correlates the averaged samples. The random walk is read from the curve's rise: a recording is
refused unless that rise (where the random walk holds 90 % of the variance) lasts ``RW_CLUSTERS``
clusters, with the duration it would need.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import allantools
import numpy as np
from scipy.ndimage import median_filter
from scipy.optimize import nnls

from vical.calib.errors import CalibrationError
from vical.data import NS_PER_S, ImuNoise, ImuSamples

AXES = ("gyro x", "gyro y", "gyro z", "accel x", "accel y", "accel z")
UNITS = {"gyro": "rad/s", "accel": "m/s^2"}
EXPONENTS = np.array([-1, 0, 1])  # Allan variance terms c_k tau^k: white noise, flat floor, random walk
BIAS_INSTABILITY_FACTOR = 0.664  # sqrt(2 ln 2 / pi): flicker noise's floor is 0.664 B
MIN_CLUSTERS = 10  # a deviation from fewer non-overlapping clusters is too noisy to read a line from
FIT_MIN_SAMPLES = 10  # below this many samples per cluster an IMU's low-pass filter shapes the curve
RW_SHARE = 0.9  # the random walk is read where it holds this share of the Allan variance ...
RW_CLUSTERS = 100  # ... over at least this many clusters (measured: K within 10 % (1 sigma) then)
TAUS_PER_DECADE = 20
FLOOR_GAIN = 0.1  # the flat floor enters the fit only when it cuts the residual tenfold (fit_terms)
FIT_ROUNDS = 4  # reweighting rounds: weights from the fitted curve, not from the noisy measured one
# Motion: 1 s means against the 10 s around them (slow bias drift follows), beyond 10x the noise (check_static).
MOTION_WINDOW_S, MOTION_HALF_WINDOWS, MOTION_SIGMAS = 1.0, 10, 10.0
# Below this length the duration is checked before the motion. The motion check alone refused static
# streams of the noisiest IMU of the tests (40 seeds each): 30 s 14 (up to 14x), 60 s 3, 90 s and longer none.
MOTION_FIRST_S = 120.0
MIN_RATE_HZ = 10.0
MAX_MISSING = 0.10  # share of missing samples beyond which an evenly sampled stream is a fiction

Progress = Callable[[int], None]  # called with the number of averaging times just computed


class NoiseIdentificationError(CalibrationError):
    """A recording from which no IMU noise parameters can be read (moving, too short, unevenly sampled)."""


@dataclass(frozen=True)
class AllanCurve:
    """Overlapping Allan deviation of one axis.

    Attributes:
        tau: (T,) [s] averaging times, increasing.
        adev: (T,) [unit] Allan deviation, in the readings' unit (rad/s or m/s^2).
        clusters: (T,) number of non-overlapping clusters of length tau in the recording.
    """

    tau: np.ndarray
    adev: np.ndarray
    clusters: np.ndarray


@dataclass(frozen=True)
class AxisNoise:
    """The noise parameters of one axis, read from its Allan deviation.

    Attributes:
        axis: ``"gyro x"`` ... ``"accel z"``.
        noise_density: N [rad/s/sqrt(Hz) or m/s^2/sqrt(Hz)]: the -1/2 line at tau = 1 s.
        random_walk: K [rad/s^2/sqrt(Hz) or m/s^3/sqrt(Hz)]: the +1/2 line at tau = 3 s.
        bias_instability: B [rad/s or m/s^2]: the fitted curve's minimum / 0.664.
        tau_min: [s] averaging time of the fitted curve's minimum (within the measured taus).
        coefficients: (3,) the fitted Allan variance ``c_-1 / tau + c_0 + c_1 tau`` [unit^2 s^k].
        coefficients_without_floor: (3,) the fit of white noise and random walk alone (``c_0 = 0``).
        curve: the Allan deviation the values were read from.
    """

    axis: str
    noise_density: float
    random_walk: float
    bias_instability: float
    tau_min: float
    coefficients: np.ndarray
    coefficients_without_floor: np.ndarray
    curve: AllanCurve

    @property
    def unit(self) -> str:
        """Unit of the readings: ``rad/s`` or ``m/s^2``."""
        return UNITS[self.axis.split()[0]]

    def model(self, tau: np.ndarray) -> np.ndarray:
        """[unit] the fitted Allan deviation at ``tau`` (T,) [s]."""
        return np.sqrt(np.power.outer(np.asarray(tau, dtype=float), EXPONENTS) @ self.coefficients)

    def white_line(self, tau: np.ndarray) -> np.ndarray:
        """[unit] the slope -1/2 line ``N / sqrt(tau)`` at ``tau`` [s]."""
        return self.noise_density / np.sqrt(tau)

    def walk_line(self, tau: np.ndarray) -> np.ndarray:
        """[unit] the slope +1/2 line ``K sqrt(tau / 3)`` at ``tau`` [s]."""
        return self.random_walk * np.sqrt(np.asarray(tau) / 3.0)

    def rise_tau(self, floor: bool = True) -> float:
        """[s] the averaging time from which the random walk holds ``RW_SHARE`` of the variance (inf: never).

        ``floor=False``: of the fit without the flat floor, where the rise comes earlier.
        """
        return _rise_tau(self.coefficients if floor else self.coefficients_without_floor)


def _rise_tau(coefficients: np.ndarray) -> float:
    """[s] where ``c_1 tau`` holds ``RW_SHARE`` of ``c_-1 / tau + c_0 + c_1 tau`` (inf when ``c_1 = 0``)."""
    white, floor, walk = coefficients
    if walk <= 0:
        return float("inf")
    # walk tau = r (white / tau + floor), r = share / (1 - share): the positive root of the quadratic
    r = RW_SHARE / (1.0 - RW_SHARE)
    return float((r * floor + np.sqrt((r * floor) ** 2 + 4 * walk * r * white)) / (2 * walk))


@dataclass(frozen=True)
class NoiseIdentification:
    """Noise parameters of the six axes of a static recording.

    Attributes:
        axes: six ``AxisNoise``, gyro x y z then accel x y z.
        rate_hz: [Hz] sample rate of the recording.
        duration_s: [s] length of the recording.
    """

    axes: tuple[AxisNoise, ...]
    rate_hz: float
    duration_s: float

    def sensor(self, name: str) -> tuple[AxisNoise, ...]:
        """The three axes of ``"gyro"`` or ``"accel"``."""
        return tuple(a for a in self.axes if a.axis.startswith(name))

    def imu_noise(self, rate_hz: float | None = None) -> ImuNoise:
        """Kalibr's one value per sensor: the largest of its three axes (a filter told too little noise
        trusts the IMU more than it deserves; too much only weighs it down). ``rate_hz``: the
        ``update_rate`` to write (default: the measured rate)."""
        gyro, accel = self.sensor("gyro"), self.sensor("accel")
        return ImuNoise(
            accel_noise_density=max(a.noise_density for a in accel),
            accel_random_walk=max(a.random_walk for a in accel),
            gyro_noise_density=max(a.noise_density for a in gyro),
            gyro_random_walk=max(a.random_walk for a in gyro),
            rate_hz=self.rate_hz if rate_hz is None else rate_hz,
        )


def inflate(noise: ImuNoise, density_factor: float, walk_factor: float) -> ImuNoise:
    """``noise`` with its white-noise densities times ``density_factor`` and random walks times ``walk_factor``."""
    return ImuNoise(
        accel_noise_density=noise.accel_noise_density * density_factor,
        accel_random_walk=noise.accel_random_walk * walk_factor,
        gyro_noise_density=noise.gyro_noise_density * density_factor,
        gyro_random_walk=noise.gyro_random_walk * walk_factor,
        rate_hz=noise.rate_hz,
    )


def identify_noise(imu: ImuSamples, where: str, progress: Progress | None = None) -> NoiseIdentification:
    """The noise parameters of a static recording's six axes (see the module docstring).

    Raises ``NoiseIdentificationError`` naming ``where`` (the input) for a stream sampled below
    10 Hz or with many samples missing, one that moves, and one too short to show the random walk
    (with the duration it would need). A recording shorter than ``MOTION_FIRST_S`` is checked for its
    length before its motion: its few 1 s means tell a resting IMU's bias drift from motion poorly, and
    a recording that short is mostly refused as too short whatever it does.
    """
    rate = sample_rate(imu, where)
    duration = len(imu) / rate
    motion_first = duration >= MOTION_FIRST_S
    if motion_first:
        check_static(imu, rate, where)
    m = averaging_factors(len(imu))
    if len(m) == 0 or m[-1] < 10 * FIT_MIN_SAMPLES:
        raise NoiseIdentificationError(
            f"{where}: {format_duration(duration)} of IMU data is far too short to read the noise from; "
            "record the IMU lying still for hours"
        )
    readings = np.hstack([imu.gyro, imu.accel])
    curves = [allan_deviation(readings[:, k], rate, m, progress) for k in range(len(AXES))]
    axes = tuple(read_axis(name, curve, rate) for name, curve in zip(AXES, curves, strict=True))
    check_duration(axes, duration, where)
    if not motion_first:
        check_static(imu, rate, where)
    return NoiseIdentification(axes, rate, duration)


# ------------------------------------------------------------------------------ the recording
def sample_rate(imu: ImuSamples, where: str) -> float:
    """[Hz] the stream's rate from its median sample interval; refuses a rate too low or too many missing samples.

    A few missing samples are tolerated: the Allan deviation treats the stream as evenly sampled.
    """
    if len(imu) < 3:
        raise NoiseIdentificationError(f"{where}: {len(imu)} IMU samples; record the IMU lying still for hours")
    dt = np.diff(imu.t)
    rate = NS_PER_S / float(np.median(dt))
    if rate < MIN_RATE_HZ:
        raise NoiseIdentificationError(
            f"{where}: the IMU samples at {rate:.3g} Hz (median interval {np.median(dt) / 1e6:.4g} ms); reading its "
            f"white noise needs {MIN_RATE_HZ:g} Hz or more: check that the timestamps are in ns"
        )
    missing = 1.0 - len(imu) / ((imu.t[-1] - imu.t[0]) / NS_PER_S * rate + 1)
    if missing > MAX_MISSING:
        worst = int(np.argmax(dt))
        raise NoiseIdentificationError(
            f"{where}: {missing:.0%} of the samples at {rate:.4g} Hz are missing (the longest gap: "
            f"{dt[worst] / NS_PER_S:.3g} s at {(imu.t[worst] - imu.t[0]) / NS_PER_S:.1f} s); the Allan deviation "
            "needs an evenly sampled stream: record again without drops, or cut the gaps out (--start, --end)"
        )
    return rate


def check_static(imu: ImuSamples, rate_hz: float, where: str) -> None:
    """Refuse a recording that moves: its 1 s means changing far beyond the noise.

    Two statistics per axis, each in units of its own robust spread over the recording (white noise,
    bias drift and all: a static recording passes whatever its IMU):

    - bump: a 1 s mean's departure from the median of the 21 s around it;
    - tilt: the median of the next 10 s minus that of the last 10 s, a lasting shift (gravity moved
      on the accelerometer), which the running median follows at once and would hide.
    """
    n = max(1, round(MOTION_WINDOW_S * rate_hz))
    windows = len(imu) // n
    if windows < 2 * MOTION_HALF_WINDOWS + 1:
        return  # too short to tell; the duration check refuses it
    readings = np.hstack([imu.gyro, imu.accel])
    means = readings[: windows * n].reshape(windows, n, 6).mean(axis=1)
    white = np.std(np.diff(readings, axis=0), axis=0) / np.sqrt(2 * n)  # the scale when a spread is 0
    bump = means - median_filter(means, size=(2 * MOTION_HALF_WINDOWS + 1, 1), mode="nearest")
    change, ratio = np.zeros_like(means), np.zeros_like(means)
    for statistic in (bump, _level_shifts(means, MOTION_HALF_WINDOWS)):
        spread = 1.4826 * np.nanmedian(np.abs(statistic - np.nanmedian(statistic, axis=0)), axis=0)
        scale = np.maximum(spread, white)
        if np.any(scale == 0):
            raise NoiseIdentificationError(f"{where}: {AXES[int(np.argmax(scale == 0))]} never changes (stuck?)")
        larger = np.abs(statistic) / scale > ratio  # False where the statistic is NaN
        change[larger], ratio[larger] = statistic[larger], (np.abs(statistic) / scale)[larger]
    spans = _spans(np.any(ratio > MOTION_SIGMAS, axis=1))
    if not spans:
        return
    start, stop = spans[0]
    k, axis = np.unravel_index(np.argmax(ratio[start:stop]), ratio[start:stop].shape)
    more = f" (and in {len(spans) - 1} more spans)" if len(spans) > 1 else ""
    raise NoiseIdentificationError(
        f"{where}: the IMU moves between {start * n / rate_hz:.1f} s and {stop * n / rate_hz:.1f} s{more}: "
        f"{AXES[axis]} changes by {abs(change[start + k, axis]):.3g} {UNITS[AXES[axis].split()[0]]}, "
        f"{ratio[start + k, axis]:.0f}x its resting noise; the noise must be measured with the IMU lying still: "
        "record again, or cut the motion out (--start, --end)"
    )


def _level_shifts(means: np.ndarray, half: int) -> np.ndarray:
    """(W, D): for each window k, the median of windows k+1..k+half minus that of k-half+1..k (NaN at the ends).

    NaN, not 0, where a side is incomplete: zeros there would shrink the spread the shifts are measured
    in, most in short recordings (30 s: 19 zeros of 30 windows).
    """
    medians = np.median(np.lib.stride_tricks.sliding_window_view(means, half, axis=0), axis=-1)  # windows j..j+half-1
    shifts = np.full_like(means, np.nan)
    shifts[half - 1 : len(means) - half] = medians[half:] - medians[: len(medians) - half]
    return shifts


def _spans(flags: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of the runs of True in ``flags``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def check_duration(axes: tuple[AxisNoise, ...], duration_s: float, where: str) -> None:
    """Refuse a recording whose Allan deviation does not show the random walk's rise over ``RW_CLUSTERS`` clusters.

    The decision reads each axis's fitted curve as it is, flat floor and all. The duration stated to a
    refused recording is, where it exceeds the recording, that of the fit without the floor: a short
    curve's floor is mostly chance, and it put the stated duration at up to 44 times the true need on
    60 s streams (1.1 to 1.7 times without it, 20 seeds); a real floor delays the rise, which the
    message says ("or more").
    """
    needed = [RW_CLUSTERS * a.rise_tau() for a in axes]
    if max(needed) <= duration_s:
        return
    too_short = f"{where}: {format_duration(duration_s)} is too short to measure the bias random walk"
    without_floor = [RW_CLUSTERS * a.rise_tau(floor=False) for a in axes]
    k = int(np.argmax(without_floor))
    if duration_s < without_floor[k] < np.inf:
        raise NoiseIdentificationError(
            f"{too_short}: the Allan deviation of {axes[k].axis} rises (random walk) from about tau = "
            f"{axes[k].rise_tau(floor=False):.3g} s on, and reading that rise takes a recording {RW_CLUSTERS} "
            f"times as long; record the IMU lying still for about {format_duration(without_floor[k])} or more "
            "(more where its curve flattens out before it rises)"
        )
    k = int(np.argmax(needed))
    if np.isfinite(needed[k]):
        raise NoiseIdentificationError(
            f"{too_short}: the Allan deviation of {axes[k].axis} flattens out and rises (random walk) only from "
            f"tau = {axes[k].rise_tau():.3g} s on, and reading that rise takes a recording {RW_CLUSTERS} times as "
            f"long; record the IMU lying still for about {format_duration(needed[k])} or more"
        )
    longest = axes[k].curve.tau[-1]
    raise NoiseIdentificationError(
        f"{too_short}: the Allan deviation of {axes[k].axis} does not rise up to tau = {longest:.3g} s, the longest "
        f"averaging time this recording resolves; record the IMU lying still for far longer than "
        f"{format_duration(RW_CLUSTERS * longest)} (hours, as is common practice)"
    )


def format_duration(seconds: float) -> str:
    """``45 s``, ``12.5 min`` or ``3.2 h``."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


# ------------------------------------------------------------------------------ Allan deviation
def averaging_factors(n_samples: int, per_decade: int = TAUS_PER_DECADE) -> np.ndarray:
    """Cluster lengths m [samples]: log-spaced unique integers from 1 to ``n_samples / MIN_CLUSTERS``."""
    largest = n_samples // MIN_CLUSTERS
    if largest < 2:
        return np.ones(largest, dtype=np.int64)
    count = int(np.ceil(np.log10(largest) * per_decade)) + 1
    return np.unique(np.round(np.logspace(0, np.log10(largest), count)).astype(np.int64))


def allan_deviation(x: np.ndarray, rate_hz: float, m: np.ndarray, progress: Progress | None = None) -> AllanCurve:
    """Overlapping Allan deviation of the evenly sampled readings ``x`` (S,) at cluster lengths ``m`` [samples].

    ``progress(k)`` is called after each batch of ``k`` averaging times (hours of data take a while).
    """
    phase = allantools.frequency2phase(np.asarray(x, dtype=float), rate_hz)
    adev = np.empty(len(m))
    batch = 8
    for start in range(0, len(m), batch):
        chunk = m[start : start + batch]
        _, dev, _, _ = allantools.oadev(phase, rate=rate_hz, data_type="phase", taus=chunk / rate_hz)
        adev[start : start + len(chunk)] = dev
        if progress is not None:
            progress(len(chunk))
    return AllanCurve(m / rate_hz, adev, len(x) // m)


def fit_terms(curve: AllanCurve, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(3,) non-negative Allan variance coefficients ``c_k`` of ``sum c_k tau^k``, k = -1, 0, 1, and
    (3,) those of the fit without the floor (``c_0 = 0``).

    The flat floor (k = 0) is kept only when it cuts the weighted squared residual of the fit without
    it tenfold. On a curve without a floor its free coefficient takes a share of the random walk
    (simulated white noise + random walk, one hour: -5.7 % on the random walk on average, against
    -2.6 % without it), and chance alone cut the residual up to 7x (90 s) to 3x (30 min) there; a
    flicker floor as high as the curve's minimum cut it 15 to 120x. Leaving out a weak floor errs
    on the safe side: the white-noise and random-walk lines then cover it and come out larger.
    """
    use = curve.tau >= FIT_MIN_SAMPLES / rate_hz
    tau, var, clusters = curve.tau[use], curve.adev[use] ** 2, curve.clusters[use]
    white_and_walk, residual = _weighted_fit(tau, var, clusters, np.array([-1, 1]))
    without_floor = np.array([white_and_walk[0], 0.0, white_and_walk[1]])
    with_floor, residual_floor = _weighted_fit(tau, var, clusters, EXPONENTS)
    if residual_floor < FLOOR_GAIN * residual:
        return with_floor, without_floor
    return without_floor, without_floor


def _weighted_fit(tau: np.ndarray, var: np.ndarray, clusters: np.ndarray, exponents: np.ndarray):
    """Non-negative coefficients of ``sum c_k tau^k`` for the variances ``var``, and the weighted squared residual.

    A variance estimate's relative error falls as ``1 / sqrt(clusters)``: rows are weighted by
    ``sqrt(clusters) / sigma^2``, with ``sigma^2`` from the previous round's fit (the measured
    values as weights would favour the points that came out low).
    """
    basis = np.power.outer(tau, exponents)
    expected = var
    for _ in range(FIT_ROUNDS):
        weight = np.sqrt(clusters) / expected
        rows = basis * weight[:, None]
        scale = np.abs(rows).max(axis=0)  # the columns span decades of tau: scale them for NNLS
        solution = nnls(rows / scale, var * weight)[0] / scale
        expected = np.maximum(basis @ solution, var.min() * 1e-3)
    weight = np.sqrt(clusters) / expected
    return solution, float(np.sum(((basis @ solution - var) * weight) ** 2))


def read_axis(axis: str, curve: AllanCurve, rate_hz: float) -> AxisNoise:
    """The noise parameters of one axis from its Allan deviation (see the module docstring)."""
    c, without_floor = fit_terms(curve, rate_hz)
    white, _, walk = c
    fitted = np.sqrt(np.power.outer(curve.tau, EXPONENTS) @ c)
    k = int(np.argmin(fitted))  # the measured curve's own minimum is biased low by its noise
    return AxisNoise(
        axis=axis,
        noise_density=float(np.sqrt(white)),  # the line sqrt(white / tau) at tau = 1 s
        random_walk=float(np.sqrt(3.0 * walk)),  # the line sqrt(walk tau) at tau = 3 s
        bias_instability=float(fitted[k] / BIAS_INSTABILITY_FACTOR),
        tau_min=float(curve.tau[k]),
        coefficients=c,
        coefficients_without_floor=without_floor,
        curve=curve,
    )

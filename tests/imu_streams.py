"""Static IMU streams with known noise, for the noise identification's tests.

The streams come from the simulator's noise model (``vical.sim.imu.ImuNoiseProcess``: white noise of
sigma ``N sqrt(rate)`` per sample and a bias random walk of sigma ``K / sqrt(rate)`` per sample, Kalibr's
discretisation). ``NOISE`` puts the Allan deviation's minimum near tau = 0.5 s: a 30 min recording then
holds 3600 times it, and the tests stay fast.
"""

import numpy as np

from vical.data import NS_PER_S, ImuNoise, ImuSamples
from vical.sim.imu import ImuNoiseProcess

RATE = 50.0
NOISE = ImuNoise(accel_noise_density=0.02, accel_random_walk=0.07, gyro_noise_density=0.002,
                 gyro_random_walk=0.007, rate_hz=RATE)  # fmt: skip
GRAVITY = np.array([0.3, -0.2, 9.8])  # [m/s^2] a slightly tilted IMU at rest


def static_stream(duration_s: float, seed: int, noise: ImuNoise = NOISE) -> ImuSamples:
    """A resting IMU's samples: gravity, initial biases, white noise and bias random walk."""
    n = int(duration_s * noise.rate_hz)
    process = ImuNoiseProcess(noise, np.random.default_rng(seed), np.full(3, 0.01), np.array([0.05, -0.1, 0.2]))
    gyro, accel, _ = process.apply(np.zeros((n, 3)), np.tile(GRAVITY, (n, 1)))
    t = 1_700_000_000 * NS_PER_S + np.arange(n, dtype=np.int64) * round(NS_PER_S / noise.rate_hz)
    return ImuSamples(t, gyro, accel)


def truths(noise: ImuNoise) -> tuple[np.ndarray, np.ndarray]:
    """(6,) noise densities and (6,) random walks, gyro x y z then accel x y z."""
    density = np.repeat([noise.gyro_noise_density, noise.accel_noise_density], 3)
    walk = np.repeat([noise.gyro_random_walk, noise.accel_random_walk], 3)
    return density, walk

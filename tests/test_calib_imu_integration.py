"""The calibrator's IMU integration against a motion whose preintegrated deltas are known in closed form."""

import gtsam
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vical.calib.solve.imu_integration import (
    cubic_interpolate,
    interval_segments,
    preintegrate,
    preintegration_params,
    reading_interpolant,
)
from vical.data import ImuNoise

GRAVITY = np.array([0.0, 0.0, -9.81])
RATE_HZ = 200.0


def _tremor(t: np.ndarray):
    """A hand's reach with a 10 Hz tremor (1 mm, 0.3 deg) on top: positions, velocities, accelerations (N, 3)
    and the angle (N,), rate, about one fixed axis."""
    w = 2.0 * np.pi * 10.0
    amplitude = np.array([1.0e-3, 0.8e-3, 1.2e-3])
    phase = np.array([0.3, 1.1, 2.0])
    reach = np.array([0.2, -0.1, 0.05])  # m/s^2, steady
    arg = w * t[:, None] + phase
    p = amplitude * np.sin(arg) + 0.5 * reach * t[:, None] ** 2
    v = amplitude * w * np.cos(arg) + reach * t[:, None]
    a = -amplitude * w**2 * np.sin(arg) + reach
    angle = np.radians(0.3) * np.sin(w * 1.1 * t) + 0.4 * t
    rate = np.radians(0.3) * w * 1.1 * np.cos(w * 1.1 * t) + 0.4
    return p, v, a, angle, rate


def _readings(t: np.ndarray, axis: np.ndarray):
    """The ideal gyro and accelerometer of ``_tremor`` as an IMU samples them at ``t``: each reading the mean over its
    sample interval centred on its stamp (its decimation filter; midpoint rule on 64 sub-samples)."""
    h = 1.0 / RATE_HZ
    sub = t[:, None] + h * ((np.arange(64) + 0.5) / 64 - 0.5)
    _, _, a, angle, rate = _tremor(sub.ravel())
    R = Rotation.from_rotvec(angle[:, None] * axis).as_matrix()
    specific_force = np.einsum("nji,nj->ni", R, a - GRAVITY).reshape(len(t), 64, 3).mean(axis=1)
    return rate.reshape(len(t), 64).mean(axis=1)[:, None] * axis, specific_force


def _deltas(ta: float, tb: float, axis: np.ndarray):
    """The exact preintegrated rotation, velocity and position from ``ta`` to ``tb`` (GTSAM's definitions)."""
    p, v, _, angle, _ = _tremor(np.array([ta, tb]))
    R_a = Rotation.from_rotvec(angle[0] * axis).as_matrix()
    R_b = Rotation.from_rotvec(angle[1] * axis).as_matrix()
    dt = tb - ta
    dR = R_a.T @ R_b
    dV = R_a.T @ (v[1] - v[0] - GRAVITY * dt)
    dP = R_a.T @ (p[1] - p[0] - v[0] * dt - 0.5 * GRAVITY * dt**2)
    return dR, dV, dP


def test_cubic_interpolation_is_exact_for_a_cubic_at_any_spacing():
    t = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.004, 0.006, 20)])
    x = np.stack([1.0 + 2.0 * t - 3.0 * t**2 + 40.0 * t**3, t**3], axis=1)
    tq = np.linspace(t[0], t[-1], 57)
    expected = np.stack([1.0 + 2.0 * tq - 3.0 * tq**2 + 40.0 * tq**3, tq**3], axis=1)
    np.testing.assert_allclose(cubic_interpolate(t, x, tq), expected, atol=1e-12)


def test_the_motion_is_recovered_exactly_from_the_interval_means_of_a_cubic():
    """Readings that are a cubic motion's means over their intervals (f + f'' h^2 / 24): the interpolant gives the
    motion itself between the third and the third-to-last reading (the first and last keep their value)."""
    h = 0.005
    t = np.arange(20) * h
    f = lambda x: np.stack([1.0 + 2.0 * x - 3.0 * x**2 + 40.0 * x**3, 5.0 * x**3], axis=-1)  # noqa: E731
    f2 = lambda x: np.stack([-6.0 + 240.0 * x, 30.0 * x], axis=-1)  # noqa: E731
    means = f(t) + f2(t) * h**2 / 24.0
    tq = np.linspace(t[2], t[-3], 41)
    np.testing.assert_allclose(reading_interpolant(t, means, tq), f(tq), atol=1e-12)
    assert np.abs(cubic_interpolate(t, means, tq) - f(tq)).max() > 1e-6  # taken as point values they are not


@pytest.mark.parametrize("offset", [0.0, 0.0013])
def test_a_tremor_sampled_at_200_hz_integrates_to_its_exact_deltas(offset):
    """Between two camera instants 0.1 s apart (not on the samples), a 10 Hz tremor on a slow turn and reach, read
    as an IMU's interval means: the preintegrated deltas against the closed form. Measured: 1.2-1.4 um, 3.9-4.2
    um/s, 0.09-0.19 urad. The readings' linear interpolant by the trapezoid rule (the integration before) shrinks the
    tremor by (2 pi 10 Hz / 200 Hz)^2 / 12 = 0.8 % and the interval mean by another 0.4 %: 85 um, 119-158 um/s and
    4-10 urad here, the error that cost hand-held 200 Hz calibrations 3-7 mm of their translation
    (tests/test_hand_held.py); the cubic of the readings taken as point values 29 um, 45 um/s, 1.5-3.3 urad."""
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    t = np.arange(0.0, 0.5, 1.0 / RATE_HZ)
    gyro, accel = _readings(t, axis)
    ta, tb = 0.2 + offset, 0.3 + offset + 0.0021
    noise = ImuNoise(rate_hz=RATE_HZ)
    pim = preintegrate(
        preintegration_params(noise), gtsam.imuBias.ConstantBias(), interval_segments(t, gyro, accel, ta, tb)
    )
    dR, dV, dP = _deltas(ta, tb, axis)
    assert pim.deltaTij() == pytest.approx(tb - ta, abs=1e-12)
    assert np.linalg.norm(Rotation.from_matrix(pim.deltaRij().matrix().T @ dR).as_rotvec()) < 3e-7
    assert np.linalg.norm(pim.deltaVij() - dV) < 1e-5
    assert np.linalg.norm(pim.deltaPij() - dP) < 2e-6

"""The paper's error metrics and the absolute errors, on hand-computed cases."""

import numpy as np
import pytest

from vical.calib.metrics import calibration_errors, extrinsic_relative_error, group_errors_px, intrinsic_relative_error
from vical.calib.result import CalibrationResult, ResidualStats
from vical.data import SensorTruth
from vical.geometry import CameraModel, euler_to_matrix, make_transform


def test_intrinsic_relative_error_is_the_norm_of_fx_fy_cx_cy():
    truth = CameraModel("radtan", 640, 480, 500.0, 500.0, 320.0, 240.0)
    est = truth.with_intrinsics(503.0, 496.0, 320.0, 240.0, truth.dist)
    expected = 100 * 5.0 / np.linalg.norm([500, 500, 320, 240])
    assert np.isclose(intrinsic_relative_error(est, truth), expected)
    assert intrinsic_relative_error(truth, truth) == 0.0


def test_group_errors_of_focal_length_principal_point_and_distortion_at_the_corner():
    truth = CameraModel("radtan", 640, 480, 500.0, 510.0, 320.0, 240.0, np.array([-0.2, 0.05, 0.0, 0.0]))
    est = truth.with_intrinsics(500.3, 509.6, 320.6, 240.8, truth.dist + [1e-4, 0.0, 0.0, 0.0])
    errors = group_errors_px(est, truth)
    assert errors["focal"] == pytest.approx(0.5) and errors["principal_point"] == pytest.approx(1.0)
    # k1 adds x r^2 dk1 to the normalised corner (x, y): (fx x, fy y) r^2 dk1 in px, to first order
    x, y = 319.0 / 500.0, 239.0 / 510.0
    r2 = x * x + y * y
    expected = np.hypot(500.0 * x, 510.0 * y) * r2 * 1e-4
    assert errors["distortion"] == pytest.approx(expected, rel=1e-3)
    fisheye = CameraModel("equidistant", 640, 480, 500.0, 510.0, 320.0, 240.0)
    assert group_errors_px(fisheye, truth)["distortion"] is None  # coefficients of another model: not comparable


def test_extrinsic_relative_error_of_the_12_vector():
    T_true = make_transform(np.eye(3), [0.0, 0.1, 0.06])
    T_est = make_transform(euler_to_matrix([0.0, 0.0, 0.01]), [0.003, 0.1, 0.06])
    # ||Rz(a) - I||_F^2 = 2 (1 - cos a)^2 + 2 sin^2 a = 4 (1 - cos a); ||I||_F^2 = 3.
    d_R = 2.0 * np.sqrt(1.0 - np.cos(0.01))
    expected = 100 * np.hypot(d_R, 0.003) / np.sqrt(3.0 + 0.1**2 + 0.06**2)
    assert np.isclose(extrinsic_relative_error(T_est, T_true), expected)


def test_absolute_errors_in_px_deg_mm_ms():
    truth_cam = CameraModel("radtan", 640, 480, 500.0, 500.0, 320.0, 240.0)
    truth = SensorTruth(truth_cam, make_transform(np.eye(3), [0.0, 0.1, 0.06]), time_offset=0.010)
    est_cam = truth_cam.with_intrinsics(503.0, 496.0, 321.0, 240.0, truth_cam.dist)
    T_est = make_transform(euler_to_matrix([0.0, 0.0, np.deg2rad(0.5)]), [0.003, 0.1, 0.056])
    result = CalibrationResult(
        "joint", est_cam, T_est, 0.0125, np.zeros(3), np.zeros(3), np.zeros(3), [], np.zeros(0),
        np.zeros((0, 0)), [], ResidualStats.of(np.zeros((0, 2))), np.zeros((0, 2)), np.zeros(0, int), None,
        0.3, 1, 0.1, "converged", 10,
    )  # fmt: skip
    errors = calibration_errors(result, truth)
    np.testing.assert_allclose(errors.intrinsic_abs_px, [3.0, 4.0, 1.0, 0.0])
    assert np.isclose(errors.rotation_deg, 0.5)
    assert np.isclose(errors.translation_mm, 5.0)  # |(3, 0, -4)| mm
    assert np.isclose(errors.time_offset_ms, 2.5)

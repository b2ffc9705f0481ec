"""The paper's error metrics and the absolute errors, on hand-computed cases."""

import numpy as np

from vical.calib.metrics import extrinsic_relative_error, intrinsic_relative_error
from vical.geometry import CameraModel, euler_to_matrix, make_transform


def test_intrinsic_relative_error_is_the_norm_of_fx_fy_cx_cy():
    truth = CameraModel("radtan", 640, 480, 500.0, 500.0, 320.0, 240.0)
    est = truth.with_intrinsics(503.0, 496.0, 320.0, 240.0, truth.dist)
    expected = 100 * 5.0 / np.linalg.norm([500, 500, 320, 240])
    assert np.isclose(intrinsic_relative_error(est, truth), expected)
    assert intrinsic_relative_error(truth, truth) == 0.0


def test_extrinsic_relative_error_of_the_12_vector():
    T_true = make_transform(np.eye(3), [0.0, 0.1, 0.06])
    T_est = make_transform(euler_to_matrix([0.0, 0.0, 0.01]), [0.003, 0.1, 0.06])
    d_R = np.linalg.norm(T_est[:3, :3] - np.eye(3))
    expected = 100 * np.hypot(d_R, 0.003) / np.sqrt(3.0 + 0.1**2 + 0.06**2)
    assert np.isclose(extrinsic_relative_error(T_est, T_true), expected)

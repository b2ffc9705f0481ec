"""``results-imucam.txt``: Kalibr's results layout from a real solve, its numbers the result's own, and its verdicts
("Is this a good result") right on an IMU exactly as declared and on one five times noisier than declared; the
report's IMU residual page with its 3-sigma bounds of the declared noise, which the noisier IMU's residuals leave."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest

from vical.calib.report.figures import imu_residual_page
from vical.calib.report.kalibr_results import kalibr_results_text
from vical.calib.solve.pipeline import calibrate_joint
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise, Target
from vical.geometry import CameraModel, make_transform, so3_exp
from vical.io.kalibr import kalibr_intrinsics

DECLARED = ImuNoise()
HEADINGS = ["Calibration results", "Normalized Residuals", "Residuals", "Transformation (cam0):",
            "Calibration configuration", "IMU configuration", "Is this a good result"]  # fmt: skip


@pytest.fixture(scope="module", params=[1.0, 5.0], ids=["IMU as declared", "IMU 5x noisier"])
def solved(request):
    rec = make_recording(duration=10.0, imu_noise=DECLARED.scaled(request.param), pixel_sigma=0.3, seed=40003,
                         time_offset=0.01)  # fmt: skip
    result = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), DECLARED)
    return request.param, rec, result, kalibr_results_text({"cam0": result}, rec.target)


def stats(text: str, label: str) -> tuple[float, float, float]:
    line = next(line for line in text.splitlines() if line.startswith(label))
    return tuple(float(v) for v in re.search(r"mean (\S+), median (\S+), std: (\S+)", line).groups())


def matrix_after(text: str, heading: str) -> np.ndarray:
    lines = text.splitlines()
    start = lines.index(heading) + 1
    return np.array([[float(v) for v in line.strip(" []").split()] for line in lines[start : start + 4]])


def test_the_sections_are_kalibrs_in_its_order(solved):
    *_, text = solved
    lines = text.splitlines()
    assert [lines.index(h) for h in HEADINGS] == sorted(lines.index(h) for h in HEADINGS)


def test_the_residuals_transforms_and_time_shift_are_the_results_own(solved):
    _, _, result, text = solved
    raw = stats(text, "Reprojection error (cam0) [px]:")
    norms = np.linalg.norm(result.reprojection_residuals, axis=1)
    assert raw == pytest.approx((norms.mean(), np.median(norms), norms.std()), rel=1e-5)
    normalised = stats(text, "Reprojection error (cam0):")
    assert normalised == pytest.approx(tuple(v / result.pixel_sigma for v in raw), rel=1e-4)
    # the corner noise is measured from these residuals: their whitened norms average a 2-vector's, sqrt(pi / 2)
    assert normalised[0] == pytest.approx(math.sqrt(math.pi / 2), rel=0.05)
    imu = result.imu_residuals
    gyro = np.linalg.norm(imu.gyro_measured - imu.gyro_predicted, axis=1)
    assert stats(text, "Gyroscope error (imu0) [rad/s]:")[0] == pytest.approx(gyro.mean(), rel=1e-5)
    whitened = gyro * np.sqrt(imu.dt) / DECLARED.gyro_noise_density
    assert stats(text, "Gyroscope error (imu0):")[0] == pytest.approx(whitened.mean(), rel=1e-5)
    T_ci, T_ic = matrix_after(text, "T_ci:  (imu0 to cam0): "), matrix_after(text, "T_ic:  (cam0 to imu0): ")
    np.testing.assert_allclose(T_ci, result.T_cam_imu, atol=1e-8)
    np.testing.assert_allclose(T_ic @ T_ci, np.eye(4), atol=1e-7)
    shift = float(text.splitlines()[text.splitlines().index("timeshift cam0 to imu0: [s] (t_imu = t_cam + shift)") + 1])
    assert shift == pytest.approx(result.time_offset, abs=1e-12) and shift == pytest.approx(0.01, abs=5e-4)
    assert f"Noise density (discrete): {DECLARED.gyro_noise_density * math.sqrt(200):.6g}" in text


def test_the_verdict_names_an_imu_noisier_than_declared_and_what_to_do(solved):
    scale, _, result, text = solved
    verdicts = text.split("Is this a good result")[1]
    assert "[ok] reprojection rms of cam0" in verdicts
    if scale == 1.0:
        assert "[ok] IMU noise measured from its residuals" in verdicts
    else:
        assert result.imu_noise_scale > 2.0
        assert "[check] IMU noise measured from its residuals" in verdicts and "vical-imu-noise" in verdicts


def test_the_residual_page_bounds_each_axis_by_three_sigma_of_the_declared_noise(solved):
    scale, rec, result, _ = solved
    imu = result.imu_residuals
    assert imu.noise == DECLARED and rec.truth.imu_noise == DECLARED.scaled(scale)  # declared, not as reweighted
    page = imu_residual_page(result)
    inside = []
    sensors = [(imu.gyro_measured - imu.gyro_predicted, DECLARED.gyro_noise_density),
               (imu.accel_measured - imu.accel_predicted, DECLARED.accel_noise_density)]  # fmt: skip
    for k, ax in enumerate(page.axes):  # rows x, y, z; columns gyro, accel
        residuals, density = sensors[k % 2]
        residual = residuals[:, k // 2]
        data, upper, lower = (line.get_ydata() for line in ax.lines[:3])
        np.testing.assert_array_equal(data, residual)
        np.testing.assert_allclose(upper, 3 * density / np.sqrt(imu.dt), rtol=1e-12)  # a mean of white noise over dt
        np.testing.assert_allclose(lower, -upper, rtol=1e-12)
        share = 100 * np.mean(np.abs(residual) <= upper)
        assert f"{share:.1f} % within 3 sigma" in ax.get_title()
        inside.append(share)
    if scale == 1.0:  # as declared: every residual within (the fit absorbs part of the noise: 85 intervals, 0 out)
        assert min(inside) >= 99.0, inside
    else:  # five times noisier than declared: every axis shows it (measured 79-98 % within, 90 % on average)
        assert max(inside) < 99.0 and np.mean(inside) < 95.0, inside


def field(text: str, label: str, after: str = "") -> str:
    """The value of the first line ``label ...`` after the line ``after`` (as a script that reads Kalibr's file)."""
    lines = text.splitlines()
    start = lines.index(after) if after else 0
    return next(line.strip().removeprefix(label).strip() for line in lines[start:] if line.strip().startswith(label))


def test_the_configuration_names_each_field_as_kalibr_does(solved):
    _, rec, result, text = solved
    k = kalibr_intrinsics(result.camera)
    assert field(text, "Camera model:", "cam0") == "pinhole" == k["camera_model"]
    assert [float(v) for v in field(text, "Focal length:", "cam0").strip("[]").split(",")] == k["intrinsics"][:2]
    assert [float(v) for v in field(text, "Principal point:", "cam0").strip("[]").split(",")] == k["intrinsics"][2:]
    assert field(text, "Distortion model:", "cam0") == "radtan"
    assert [float(v) for v in field(text, "Distortion coefficients:", "cam0").strip("[]").split(",")] == list(
        result.camera.dist
    )
    board = rec.target  # a checkerboard: its rows and columns of inner corners and their spacing
    assert field(text, "Type:", "cam0") == "checkerboard"
    assert field(text, "Count:", "  Rows") == str(board.rows) and field(text, "Count:", "  Cols") == str(board.cols)
    assert field(text, "Distance:", "  Rows") == f"{board.row_spacing!r} [m]"
    assert field(text, "Update rate:", "IMU configuration") == "200.0"
    assert "Baselines:" not in text  # one camera


def test_a_rigs_baselines_are_each_camera_to_the_next_with_their_length(solved):
    _, _, result, _ = solved
    T_cam1_cam0 = make_transform(so3_exp(np.array([0.0, 0.02, -0.01])), np.array([-0.11, 0.003, 0.001]))
    cam1 = replace(result, T_cam_imu=T_cam1_cam0 @ result.T_cam_imu)
    text = kalibr_results_text({"cam0": result, "cam1": cam1}, Target.aprilgrid(6, 6, 0.088, 0.3))
    lines = text.splitlines()
    assert lines[lines.index("Baselines:") + 1] == "----------"
    np.testing.assert_allclose(matrix_after(text, "Baseline (cam0 to cam1): "), T_cam1_cam0, atol=1e-8)
    assert float(field(text, "baseline norm:").removesuffix("[m]")) == pytest.approx(0.11004, abs=1e-5)
    assert lines.index("Baselines:") > lines.index("timeshift cam1 to imu0: [s] (t_imu = t_cam + shift)")
    assert lines.index("Baselines:") < lines.index("Gravity vector in target coords: [m/s^2]")
    # an aprilgrid under each camera: its tags, their size and the gap between them
    for camera in ("cam0", "cam1"):
        assert field(text, "Type:", camera) == "aprilgrid"
        assert field(text, "Rows:", camera) == "6" and field(text, "Size:", camera) == "0.088 [m]"
        assert field(text, "Spacing", camera) == f"{0.088 * 0.3!r} [m]"


@pytest.mark.parametrize(("model", "coeffs", "names"), [("ds", [-0.2, 0.6], ["DS xi:", "DS alpha:"]),
                                                        ("eucm", [0.6, 1.1], ["EUCM alpha:", "EUCM beta:"]),
                                                        ("omni", [0.9], ["Omni xi:"])])  # fmt: skip
def test_a_wide_angle_camera_names_its_projections_coefficients_as_kalibr_does(solved, model, coeffs, names):
    _, rec, result, _ = solved
    camera = CameraModel.from_hfov(2.6, distortion=model, dist=np.array(coeffs))
    text = kalibr_results_text({"cam0": replace(result, camera=camera)}, rec.target)
    assert field(text, "Camera model:", "cam0") == model and field(text, "Distortion model:", "cam0") == "none"
    assert [float(field(text, name, "cam0")) for name in names] == coeffs
    assert [float(v) for v in field(text, "Focal length:", "cam0").strip("[]").split(",")] == [camera.fx, camera.fy]

"""Noise settings: bad values refused by key, implausible ones warned about, wrong ones measured and corrected."""

import math
import re

import gtsam
import numpy as np
import pytest

from vical.calib.errors import CalibrationError
from vical.calib.metrics import calibration_errors
from vical.calib.solve.checks import check_imu_noise, check_memory, estimated_memory_mb
from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.solve.observations import collect_observations
from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint
from vical.calib.solve.variance import used_dof
from vical.calib.solve.vi_graph import solve_rounds
from vical.calib.solve.vi_problem import ViOptions, initial_estimate, prepare_problem
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise, Target

BIASES = {"gyro_bias": [0.01, -0.02, 0.005], "accel_bias": [0.05, -0.1, 0.08]}  # [rad/s], [m/s^2]
PAPER = ImuNoise()


def recording(seed: int = 5, true_noise: ImuNoise = PAPER, **kwargs):
    """20 s at 20 Hz in front of Kalibr's aprilgrid (partial views), the paper's IMU unless told otherwise."""
    return make_recording(
        duration=20.0, camera_rate_hz=20.0, target=Target.aprilgrid(), seed=seed, time_offset=0.01,
        imu_noise=true_noise, pixel_sigma=0.3, **BIASES, **kwargs,
    )  # fmt: skip


@pytest.mark.parametrize("field, key", [("accel_noise_density", "accelerometer_noise_density"),
                                        ("gyro_random_walk", "gyroscope_random_walk")])  # fmt: skip
@pytest.mark.parametrize("bad", [0.0, -1e-3, math.nan, math.inf])
def test_impossible_noise_is_refused_naming_the_imu_yaml_key(field, key, bad):
    noise = ImuNoise(**{**PAPER.to_dict(), field: bad})
    with pytest.raises(CalibrationError, match=f"IMU noise setting {key} must be a positive finite number"):
        check_imu_noise(noise)


def test_implausible_noise_is_warned_about_and_the_solve_runs():
    rec = recording()
    noise = ImuNoise(**{**PAPER.to_dict(), "gyro_noise_density": PAPER.gyro_noise_density * 2000})
    assert len(check_imu_noise(noise)) == 1
    result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, noise)
    assert any("gyroscope_noise_density" in w and "2e+03x" in w for w in result.warnings)
    errors = calibration_errors(result, rec.truth)
    assert errors.rotation_deg < 0.1 and errors.translation_mm < 5.0


@pytest.mark.parametrize("scale", [0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0])
def test_declared_noise_from_a_tenth_to_a_hundred_times_the_truth_never_loses_a_result(scale):
    rec = recording()
    result = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), PAPER.scaled(scale))
    assert np.all(np.isfinite(result.covariance)) and np.all(np.diag(result.covariance) > 0)
    # An inflated imu.yaml is corrected to the noise the residuals show; densities below the truth keep their weight
    # (``declared-or-less``), and the residuals still show the true noise to within the bias of judging it at them.
    assert 0.4 < result.imu_noise_scale * scale < 1.5
    errors = calibration_errors(result, rec.truth)
    assert errors.rotation_deg < 0.1 and errors.translation_mm < 3.0 and errors.time_offset_ms < 0.2


def test_tiny_random_walks_against_inflated_white_noise_keep_the_uncertainty():
    """A real D435i file: white noise densities inflated 25x, random walks 100x below them (once singular)."""
    rec = recording()
    noise = ImuNoise(0.1, PAPER.accel_random_walk / 100, 0.0085, PAPER.gyro_random_walk / 100)
    result = calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), noise)
    assert np.all(np.isfinite(result.covariance))
    assert not any("singular" in w for w in result.warnings)


@pytest.mark.parametrize("k", [1.0, 3.0])
def test_the_imu_noise_factor_measures_the_true_noise(k):
    rec = recording(seed=6, true_noise=PAPER.scaled(k))
    result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, PAPER)
    assert result.imu_noise_scale == pytest.approx(k, rel=0.15)
    assert any("IMU residuals show a noise" in w for w in result.warnings) == (k > 2)


def test_redundancies_add_up_to_the_number_of_parameters():
    """The degrees of freedom each sensor spends sum to the parameters: camera + IMU + bias prior = P."""
    rec = recording()
    obs = collect_observations(rec.frames, rec.target)
    problem = prepare_problem(obs, rec.imu, rec.truth.camera, rec.target, PAPER, ViOptions(), 0.0)
    g, solution, _, _ = solve_rounds(problem, initial_estimate(problem, nominal_T_cam_imu(), 0.0), False)
    linear = g.graph.linearize(solution.values)
    ordering = gtsam.Ordering.ColamdGaussianFactorGraph(linear)
    imu = used_dof(linear, range(len(g.imu_factors)), ordering)
    camera = used_dof(linear, range(g.first_corner_factor, linear.size()), ordering)
    prior = used_dof(linear, [len(g.imu_factors)], ordering)
    zero = solution.values.zeroVectors()
    parameters = sum(zero.at(key).size for key in solution.values.keys())  # noqa: SIM118 (not a dict)
    assert imu + camera + prior == pytest.approx(parameters, abs=0.05)
    assert 0 < prior < 6  # a weak prior pins almost nothing


def test_memory_bound_is_checked_before_solving_and_names_the_stride():
    with pytest.raises(CalibrationError, match=r"keep one frame in 3 \(frame_stride=3\) or raise the limit"):
        check_memory(12_000, 1_500_000, limit_mb=1500.0, stride=1)
    assert estimated_memory_mb(600, 80_000) < 300  # a real 30 s recording: far below the default limit
    rec = recording()
    options = ViOptions(memory_limit_mb=10.0)
    with pytest.raises(CalibrationError, match="more than the limit of 10 MB"):
        calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, PAPER, options=options)


def test_frame_stride_uses_every_nth_frame():
    rec = recording()
    full = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, PAPER)
    half = calibrate_extrinsics(
        rec.frames, rec.imu, rec.target, rec.truth.camera, PAPER, options=ViOptions(frame_stride=2)
    )
    assert half.num_frames == pytest.approx(full.num_frames / 2, abs=1)
    errors = calibration_errors(half, rec.truth)
    assert errors.rotation_deg < 0.1 and errors.translation_mm < 3.0
    assert half.sigma("t_x") > full.sigma("t_x")  # fewer frames, less information


@pytest.mark.parametrize("declared_over_true", [100.0, 0.01])
def test_densities_a_hundred_times_off_are_named_with_the_values_the_residuals_show(declared_over_true):
    rec = recording(seed=6)
    declared = PAPER.scaled(declared_over_true)
    result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, declared)
    (warning,) = [w for w in result.warnings if "IMU residuals show a noise" in w]
    found = re.search(r"gyroscope_noise_density ([\d.e+-]+), accelerometer_noise_density ([\d.e+-]+)", warning)
    gyro, accel = float(found.group(1)), float(found.group(2))
    # An inflated file is reweighted to its residuals: the values match the truth. A file below the truth keeps
    # its weight, and the ratio judged there reads low (vical.calib.solve.variance), as the warning says: the values
    # still point from the declared a hundredth most of the way to the truth.
    low = 1.2 if declared_over_true > 1 else 5.0
    assert PAPER.gyro_noise_density / low < gyro < 1.2 * PAPER.gyro_noise_density
    assert PAPER.accel_noise_density / low < accel < 1.2 * PAPER.accel_noise_density
    assert ("a large excess reads low" in warning) == (declared_over_true < 1)

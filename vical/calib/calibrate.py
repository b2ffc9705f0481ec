"""Public entry points: intrinsic, extrinsic (known intrinsics), joint and two-stage calibration."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from vical.calib.checks import image_coverage_warnings
from vical.calib.errors import CalibrationError
from vical.calib.intrinsics import calibrate_intrinsics
from vical.calib.model_fit import is_model_warning
from vical.calib.observations import collect_observations
from vical.calib.result import CalibrationResult
from vical.calib.uncertainty import correlations, weak_parameters
from vical.calib.visual_inertial import ViOptions, run_visual_inertial
from vical.data import CameraFrames, ImuNoise, ImuSamples, Target
from vical.geometry import CameraModel


def calibrate_extrinsics(
    frames: CameraFrames,
    imu: ImuSamples,
    target: Target,
    camera: CameraModel,
    imu_noise: ImuNoise | None = None,
    initial_T_cam_imu: np.ndarray | None = None,
    initial_time_offset: float = 0.0,
    options: ViOptions | None = None,
) -> CalibrationResult:
    """Camera-IMU extrinsic ``T_cam_imu``, time offset and IMU biases with known intrinsics.

    Args:
        frames: camera frames with target detections (camera clock).
        imu: IMU samples (IMU clock).
        target: the calibration target.
        camera: the camera's (known) intrinsics.
        imu_noise: IMU noise densities (the paper's values if None).
        initial_T_cam_imu: (4, 4) guess (``nominal_T_cam_imu()`` if None); only its translation is
            used, the rotation comes in closed form from the gyro.
        initial_time_offset: [s] centre of the time-offset scan.
        options: solver settings (``ViOptions()`` if None).
    """
    start = time.perf_counter()
    observations = collect_observations(frames, target)
    return run_visual_inertial(
        "extrinsic", observations, imu, target, camera, imu_noise or ImuNoise(), initial_T_cam_imu,
        initial_time_offset, options or ViOptions(), start,
    )  # fmt: skip


def calibrate_joint(
    frames: CameraFrames,
    imu: ImuSamples,
    target: Target,
    model: str = "radtan",
    image_size_px: tuple[int, int] | None = None,
    imu_noise: ImuNoise | None = None,
    initial_camera: CameraModel | None = None,
    initial_T_cam_imu: np.ndarray | None = None,
    initial_time_offset: float = 0.0,
    options: ViOptions | None = None,
) -> CalibrationResult:
    """Intrinsics, distortion, ``T_cam_imu``, time offset and biases in one factor graph.

    Initialised by ``calibrate_intrinsics`` on the same frames (whose warning that the model does not fit
    the lens, if any, the result carries); arguments as in ``calibrate_intrinsics`` and ``calibrate_extrinsics``.
    """
    start = time.perf_counter()
    opts = options or ViOptions()
    intrinsic = calibrate_intrinsics(
        frames, target, model, image_size_px, initial_camera, opts.pixel_sigma, opts.huber_k,
        frame_stride=opts.frame_stride, compare_models=False,
    )  # fmt: skip
    observations = collect_observations(frames, target)
    result = run_visual_inertial(
        "joint", observations, imu, target, intrinsic.camera, imu_noise or ImuNoise(), initial_T_cam_imu,
        initial_time_offset, opts, start,
    )  # fmt: skip
    coverage = image_coverage_warnings(observations, (intrinsic.camera.width, intrinsic.camera.height))
    lens = [w for w in intrinsic.warnings if is_model_warning(w)]
    return replace(result, warnings=coverage + lens + result.warnings)


def calibrate_two_stage(
    frames: CameraFrames,
    imu: ImuSamples,
    target: Target,
    model: str = "radtan",
    image_size_px: tuple[int, int] | None = None,
    imu_noise: ImuNoise | None = None,
    initial_T_cam_imu: np.ndarray | None = None,
    initial_time_offset: float = 0.0,
    options: ViOptions | None = None,
    intrinsic_frames: CameraFrames | None = None,
) -> CalibrationResult:
    """The paper's two-stage mode: intrinsics first (optionally from other frames), then the extrinsic.

    The covariance is block-diagonal: the stages' uncertainties are not propagated into each
    other (the extrinsic block assumes the intrinsics exact), which is what the two-stage method does.
    """
    start = time.perf_counter()
    opts = options or ViOptions()
    intrinsic = calibrate_intrinsics(
        intrinsic_frames or frames, target, model, image_size_px, None, opts.pixel_sigma, opts.huber_k,
        frame_stride=opts.frame_stride,
    )  # fmt: skip
    extrinsic = calibrate_extrinsics(
        frames, imu, target, intrinsic.camera, imu_noise, initial_T_cam_imu, initial_time_offset, opts
    )
    return _combine(intrinsic, extrinsic, time.perf_counter() - start)


def _combine(intrinsic: CalibrationResult, extrinsic: CalibrationResult, elapsed: float) -> CalibrationResult:
    if intrinsic.camera != extrinsic.camera:
        raise CalibrationError("internal: the extrinsic stage did not use the intrinsic stage's camera")
    n_i, n_e = len(intrinsic.estimate), len(extrinsic.estimate)
    covariance = np.zeros((n_i + n_e, n_i + n_e))
    covariance[:n_i, :n_i] = intrinsic.covariance
    covariance[n_i:, n_i:] = extrinsic.covariance
    names = intrinsic.parameter_names + extrinsic.parameter_names
    estimate = np.concatenate([intrinsic.estimate, extrinsic.estimate])
    return replace(
        extrinsic,
        task="two_stage",
        parameter_names=names,
        estimate=estimate,
        covariance=covariance,
        weak_parameters=weak_parameters(names, covariance, extrinsic.camera),
        correlations=correlations(names, covariance),
        iterations=intrinsic.iterations + extrinsic.iterations,
        solve_time=elapsed,
        warnings=intrinsic.warnings + extrinsic.warnings,
    )

"""The camera-IMU solve's ``CalibrationResult``: each camera's parameters, covariance, residuals, frame log and
time-offset evidence.
"""

from __future__ import annotations

import time
from dataclasses import replace

import gtsam
import numpy as np

from vical.calib.frame_log import FrameLog, build_frame_log, left_out
from vical.calib.result import CalibrationResult, FramePoses, ImuResiduals, ResidualStats, TimeOffsetTrace
from vical.calib.solve.imu_intrinsics import IntrinsicImuFactor
from vical.calib.solve.initialization import MIN_INIT_CORNERS
from vical.calib.solve.intrinsics import intrinsic_names
from vical.calib.solve.model_fit import given_intrinsics_warnings, lens_misfit
from vical.calib.solve.observations import FrameObservation
from vical.calib.solve.rig import OtherCamera
from vical.calib.solve.rolling_shutter import evidence_warning, readout_in_residuals
from vical.calib.solve.time_alignment import increment_mismatch, rotation_increments
from vical.calib.solve.uncertainty import assess
from vical.calib.solve.vi_covariance import ViMarginals, parameter_covariance, widening_warning
from vical.calib.solve.vi_graph import ViGraph
from vical.calib.solve.vi_problem import (
    BIAS_NAMES,
    EXTRINSIC_NAMES,
    G_KEY,
    LINE_DELAY_NAME,
    TRACE_HALF_WIDTH,
    TRACE_POINTS,
    CameraInput,
    ViEstimate,
    ViOptions,
    ViProblem,
    row_centre,
    state_key,
)
from vical.data import CameraFrames
from vical.data.imu_model import ImuIntrinsics


def _reprojection(problem: ViProblem, g: ViGraph, values: gtsam.Values) -> tuple[np.ndarray, np.ndarray]:
    """Corner residuals (N, 2) [px] and the recording frame index (N,) of each corner."""
    frames = np.array([problem.observations[problem.frame_ids[k]].index for k in g.states])
    return g.corners.residuals(values), frames[g.corners.frame_of]


def first_frame_log(
    frames: CameraFrames, every: list[FrameObservation], problem: ViProblem, g: ViGraph, used: np.ndarray
) -> FrameLog:
    """Every input frame: its corners found and used, and why a frame was left out (``vical.calib.frame_log``)."""
    inside = {problem.frame_ids[k] for k in g.states}
    outside = [problem.observations[k].index for k in problem.frame_ids if k not in inside]
    decided = left_out(every, problem.observations, problem.outliers) | {k: "outside_imu" for k in outside}
    return build_frame_log(frames, used, min(MIN_INIT_CORNERS, problem.target.num_points), decided)


def _time_offset_trace(
    problem: ViProblem,
    frame_times: np.ndarray,
    T_target_cam: np.ndarray,
    T_cam_imu: np.ndarray,
    tau0: float,
    gyro_bias: np.ndarray,
) -> TimeOffsetTrace:
    """One camera's PnP rotation rates against the bias-corrected gyro, and the mismatch around its offset.

    Args:
        frame_times: (F,) [s] the camera's frames with a target pose (camera clock, since the recording start).
        T_target_cam: (F, 4, 4) their PnP poses; T_cam_imu: (4, 4) and tau0 [s]: the camera's estimates.
        gyro_bias: (3,) [rad/s] the estimated gyro bias.
    """
    inc = rotation_increments(frame_times, T_target_cam[:, :3, :3])
    dt = inc.t_end - inc.t_start
    R_imu_cam = T_cam_imu[:3, :3].T
    shifts = tau0 + np.linspace(-TRACE_HALF_WIDTH, TRACE_HALF_WIDTH, TRACE_POINTS)
    mismatch = increment_mismatch(problem.t_imu, problem.gyro, inc, T_cam_imu[:3, :3], gyro_bias, shifts)
    return TimeOffsetTrace(
        t_camera=0.5 * (inc.t_start + inc.t_end),
        omega_camera=(inc.theta_cam / dt[:, None]) @ R_imu_cam.T,
        t_imu=problem.t_imu,
        gyro=problem.gyro - gyro_bias,
        shifts=shifts,
        mismatch=mismatch,
    )


def _imu_residuals(g: ViGraph, values: gtsam.Values, problem: ViProblem) -> ImuResiduals:
    """Mean rates per IMU factor: measured (preintegrated, bias-corrected to first order) vs from the states, with
    the biases of each interval's first state."""
    gravity = np.asarray(values.atUnit3(G_KEY).point3()) * problem.options.gravity_magnitude
    rows = []
    for n, f, dt in g.imu_factors:
        pim = f.measurement(values) if isinstance(f, IntrinsicImuFactor) else f.preintegratedMeasurements()
        bias_hat, bias = pim.biasHat(), values.atConstantBias(state_key("b", n))
        X0, X1 = values.atPose3(state_key("x", n)), values.atPose3(state_key("x", n + 1))
        v0, v1 = values.atVector(state_key("v", n)), values.atVector(state_key("v", n + 1))
        R0 = X0.rotation().matrix()
        d_bg = np.asarray(bias.gyroscope()) - np.asarray(bias_hat.gyroscope())
        d_ba = np.asarray(bias.accelerometer()) - np.asarray(bias_hat.accelerometer())
        gyro_meas = gtsam.Rot3.Logmap(pim.deltaRij()) / dt - d_bg
        gyro_pred = gtsam.Rot3.Logmap(X0.rotation().between(X1.rotation())) / dt
        accel_meas = np.asarray(pim.deltaVij()) / dt - d_ba
        accel_pred = R0.T @ (v1 - v0 - gravity * dt) / dt
        rows.append(np.concatenate([[g.state_times[n] + 0.5 * dt], gyro_meas, gyro_pred, accel_meas, accel_pred, [dt],
                                    bias.gyroscope(), bias.accelerometer()]))  # fmt: skip
    a = np.array(rows).reshape(-1, 20)
    return ImuResiduals(a[:, 0], a[:, 1:4], a[:, 4:7], a[:, 7:10], a[:, 10:13], a[:, 13], a[:, 14:17], a[:, 17:20],
                        problem.declared_noise)  # fmt: skip


def first_camera_result(
    task: str, problem: ViProblem, g: ViGraph, solution, est: ViEstimate, iterations: int, start: float, marginals
):
    joint = task == "joint"
    values = solution.values
    camera = problem.camera
    rows = camera.height if problem.options.rolling_shutter else None
    covariance, widening, imu_terms = parameter_covariance(
        marginals, values, est.T_cam_imu, joint, not problem.options.estimate_time_offset, imu_theta=est.imu_theta,
        rows=rows, centre=row_centre(problem.options),
    )  # fmt: skip
    names = _parameter_names(camera, joint, rows is not None)
    if est.imu_theta is not None:
        names += ImuIntrinsics.parameter_names(problem.options.g_sensitivity)
    assessment = assess(names, covariance, camera)
    problem.warnings += widening_warning(names, widening) + assessment.warnings
    line_delay = _line_delay(est.readout, camera, problem.options)
    estimate = np.concatenate(
        ([camera.intrinsics, camera.dist] if joint else [])
        + [np.zeros(3), est.T_cam_imu[:3, 3], [est.tau0]]
        + ([[line_delay]] if rows is not None else [])
        + [est.accel_bias, est.gyro_bias]
        + ([] if est.imu_theta is None else [est.imu_theta])
    )
    residuals, frame_index = _reprojection(problem, g, values)
    misfit = lens_misfit(camera, g.corners.points, g.corners.measured, residuals, g.corners.frame_of)
    if not joint:  # the joint task's start judged its own model (with the other models' fit)
        problem.warnings += given_intrinsics_warnings(camera, misfit)
    evidence = None if g.corners.rolling else readout_in_residuals(g.corners, values)
    problem.warnings += evidence_warning(evidence, problem.sigma_px)
    gravity = np.asarray(values.atUnit3(G_KEY).point3()) * problem.options.gravity_magnitude
    return CalibrationResult(
        task=task,
        camera=camera,
        T_cam_imu=est.T_cam_imu,
        time_offset=est.tau0,
        gyro_bias=est.gyro_bias,
        accel_bias=est.accel_bias,
        gravity_target=gravity,
        parameter_names=names,
        estimate=estimate,
        covariance=covariance,
        unmodelled_imu=imu_terms,
        weak_parameters=assessment.weak_parameters,
        correlations=assessment.correlations,
        reprojection=ResidualStats.of(residuals),
        reprojection_residuals=residuals,
        reprojection_frames=frame_index,
        imu_residuals=_imu_residuals(g, values, problem),
        pixel_sigma=problem.sigma_px,
        iterations=iterations,
        solve_time=time.perf_counter() - start,
        status=solution.status,
        num_frames=len(g.states),
        warnings=problem.warnings,
        imu_noise_scale=problem.imu_noise_scale,
        reprojection_pixels=g.corners.measured,
        time_offset_trace=_time_offset_trace(
            problem, problem.frame_times, problem.T_target_cam, est.T_cam_imu, est.tau0, est.gyro_bias
        ),
        imu_intrinsics=_imu_intrinsics(problem.options, est),
        frame_poses=FramePoses(
            np.array([problem.observations[k].t_ns for k in problem.frame_ids], dtype=np.int64),
            np.linalg.inv(problem.T_target_cam),
        ),
        lens_misfit=misfit,
        line_delay=line_delay,
        rolling_shutter_evidence=_evident_readout(evidence, problem.sigma_px),
    )


def _evident_readout(evidence, pixel_sigma: float) -> float | None:
    return evidence.readout if evidence is not None and evidence.evident(pixel_sigma) else None


def _parameter_names(camera, joint: bool, line_delay: bool) -> list[str]:
    intrinsics = intrinsic_names(camera.distortion) if joint else []
    return intrinsics + EXTRINSIC_NAMES + ([LINE_DELAY_NAME] if line_delay else []) + BIAS_NAMES


def _line_delay(readout: float, camera, options: ViOptions) -> float | None:
    """[s/row] a camera's line delay from its readout; None for a global shutter (nothing estimated, none given)."""
    if not options.rolling_shutter and readout == 0.0:
        return None
    return readout / camera.height


def _imu_intrinsics(options: ViOptions, est: ViEstimate) -> ImuIntrinsics | None:
    """The estimated intrinsics, the given ones when they were kept fixed, or None."""
    return options.imu_intrinsics if est.imu_theta is None else ImuIntrinsics.from_vector(est.imu_theta)


def other_camera_result(
    task: str,
    problem: ViProblem,
    g: ViGraph,
    solution,
    est: ViEstimate,
    entry,
    given: CameraInput,
    first: CalibrationResult,
    marginals: ViMarginals,
):
    """Another camera's result: its parameters with the shared biases, its residuals, corners, frames and time-offset
    evidence, the shared IMU residuals."""
    other, factors, paired, frame_index = entry
    joint = task == "joint"
    values = solution.values
    camera = other.camera
    rows = camera.height if problem.options.rolling_shutter else None
    covariance, widening, imu_terms = parameter_covariance(
        marginals, values, other.T_cam_imu, joint, not problem.options.estimate_time_offset, other.index, rows=rows,
        centre=row_centre(problem.options),
    )  # fmt: skip
    names = _parameter_names(camera, joint, rows is not None)
    assessment = assess(names, covariance, camera)
    dropped = len(other.observations) - len(paired)
    unpaired = [f"{other.name}: {dropped} views without a simultaneous view of the first camera were not used"]
    notes = other.warnings + widening_warning(names, widening) + (unpaired if dropped else []) + assessment.warnings
    line_delay = _line_delay(other.readout, camera, problem.options)
    estimate = np.concatenate(
        ([camera.intrinsics, camera.dist] if joint else [])
        + [np.zeros(3), other.T_cam_imu[:3, 3], [other.tau0]]
        + ([[line_delay]] if rows is not None else [])
        + [est.accel_bias, est.gyro_bias]
    )
    residuals = factors.residuals(values)
    misfit = lens_misfit(camera, factors.points, factors.measured, residuals, factors.frame_of)
    if not joint:
        notes += [f"{other.name}: {w}" for w in given_intrinsics_warnings(camera, misfit)]
    evidence = None if factors.rolling else readout_in_residuals(factors, values)
    notes += [f"{other.name}: {w}" for w in evidence_warning(evidence, other.sigma_px)]
    used_frames = frame_index[factors.frame_of]
    trace = _time_offset_trace(problem, other.frame_times, other.T_target_cam, other.T_cam_imu, other.tau0,
                               est.gyro_bias)  # fmt: skip
    return replace(
        first,
        camera=camera,
        T_cam_imu=other.T_cam_imu,
        time_offset=other.tau0,
        estimate=estimate,
        covariance=covariance,
        unmodelled_imu=imu_terms,
        weak_parameters=assessment.weak_parameters,
        correlations=assessment.correlations,
        reprojection=ResidualStats.of(residuals),
        reprojection_residuals=residuals,
        reprojection_frames=used_frames,
        reprojection_pixels=factors.measured,
        pixel_sigma=other.sigma_px,
        num_frames=len(paired),
        warnings=notes,
        frame_log=_other_frame_log(problem, other, given, used_frames),
        time_offset_trace=trace,
        frame_poses=FramePoses(
            np.array([o.t_ns for o in other.observations], dtype=np.int64), np.linalg.inv(other.T_target_cam)
        ),
        lens_misfit=misfit,
        line_delay=line_delay,
        rolling_shutter_evidence=_evident_readout(evidence, other.sigma_px),
    )


def _other_frame_log(problem: ViProblem, other: OtherCamera, given: CameraInput, used_frames: np.ndarray):
    """Another camera's ``FrameLog`` over its own frames (None without them): its views with a target pose that no
    first-camera state took are ``unpaired``."""
    if given.frames is None:
        return None
    paired = set(used_frames.tolist())
    unpaired = {o.index: "unpaired" for o in other.observations if o.index not in paired}
    strided = given.observations[:: problem.options.frame_stride]
    decided = left_out(given.observations, strided, other.outliers) | unpaired
    return build_frame_log(given.frames, used_frames, min(MIN_INIT_CORNERS, problem.target.num_points), decided)

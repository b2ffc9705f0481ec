"""Camera-IMU calibration in one factor graph: extrinsic, time offset, biases, and optionally intrinsics.

Layout (navigation frame = target frame, so no gauge prior is needed):

- per used frame ``i``: IMU state ``X_i`` (``Pose3`` ``T_target_imu`` at IMU time
  ``t_cam_i + tau0``), velocity ``V_i`` [m/s] (target frame), bias ``B_i``;
- shared: ``E`` = ``T_imu_cam`` (``Pose3``), gravity direction ``G`` (``Unit3``, target frame),
  time-offset correction ``D`` [s] (``tau = tau0 + D``), and in the joint task the camera
  parameters ``K`` (``CameraModel.parameters``, 8 or 6);
- a rig's other cameras ``c`` (``vical.calib.solve.rig``): their own ``E_c``, ``D_c`` (and ``K_c``); their frames
  join the states of the first camera's simultaneous frames;
- factors: one corner factor per frame on ``(X_i, V_i, E, D[, K])``, which projects the known
  target points from the pose at the exposure instant ``X_i Exp([omega_i; R_i^T V_i] D) E``
  (``vical.calib.solve.corner_factors``), ``CombinedImuFactorWithGravityDirection`` between consecutive
  states (rotation-compensated midpoint preintegration), a weak prior on the first bias;
- with ``imu_model="scale-misalignment"`` the IMU intrinsics ``I`` (scale, misalignment, optionally
  the gyro's g-sensitivity) are a variable of every IMU factor (``vical.calib.solve.imu_intrinsics``), with
  a weak prior; known intrinsics (``ViOptions.imu_intrinsics``) otherwise correct the readings.

Initialisation: PnP poses with the (known or intrinsically calibrated) camera; time offset,
``R_cam_imu`` and gyro bias in closed form (``time_alignment``); translation from the guess;
velocities by finite differences; gravity from the mean specific force.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from vical.calib.errors import CalibrationError
from vical.calib.result import CalibrationResult
from vical.calib.solve.checks import check_imu_noise, check_memory
from vical.calib.solve.imu_model_error import imu_model_warnings
from vical.calib.solve.intrinsics import check_model
from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.solve.rig import OtherCamera, initialise_other, prepare_other
from vical.calib.solve.rolling_shutter import unobserved, unobserved_warning
from vical.calib.solve.vi_covariance import gap_warnings, imu_noise_warning, solution_marginals, span_warnings
from vical.calib.solve.vi_graph import measured_noise, reweighted_solve, solve_rounds
from vical.calib.solve.vi_problem import (  # noqa: F401 (GRAVITY_MAGNITUDE, NOISE_WEIGHTINGS: the public names' home)
    GRAVITY_MAGNITUDE,
    NOISE_WEIGHTINGS,
    CameraInput,
    ViEstimate,
    ViOptions,
    ViProblem,
    initial_estimate,
    prepare_problem,
    row_centre,
)
from vical.calib.solve.vi_result import first_camera_result, first_frame_log, other_camera_result
from vical.data import ImuNoise, ImuSamples, Target


def run_visual_inertial(
    task: str,
    first: CameraInput,
    imu: ImuSamples,
    target: Target,
    imu_noise: ImuNoise,
    options: ViOptions,
    start: float,
    others: list[CameraInput] | None = None,
) -> list[CalibrationResult]:
    """The camera-IMU graph of the extrinsic (``task="extrinsic"``) and joint (``task="joint"``) solves
    (``vical.calib.solve.pipeline.calibrate_rig`` calls it).

    With ``options.rolling_shutter``, a line delay the recording's motion does not tell
    (``vical.calib.solve.rolling_shutter.unobserved``) sends the whole rig back to its given line delays, solved again
    without estimating them, with a warning.

    Returns the first camera's result, then one per camera of ``others`` (a rig in one graph).
    """
    others = others or []
    camera, frames, initial_time_offset = first.camera, first.frames, first.initial_time_offset
    for c in [camera] + [o.camera for o in others]:
        check_model(c.distortion)
        if c.distortion_center_offset.any():
            raise CalibrationError("the calibrator's camera models have the distortion centre at the principal point")
    T_guess = nominal_T_cam_imu() if first.initial_T_cam_imu is None else np.asarray(first.initial_T_cam_imu, float)
    if T_guess.shape != (4, 4):
        raise CalibrationError(f"initial_T_cam_imu must be a 4 x 4 transform, got shape {T_guess.shape}")
    noise_warnings = check_imu_noise(imu_noise)
    every = first.observations
    observations = every[:: options.frame_stride]
    views = observations + [f for o in others for f in o.observations[:: options.frame_stride]]
    check_memory(len(views), sum(len(v.ids) for v in views), options.memory_limit_mb, options.frame_stride)
    problem = prepare_problem(
        observations, imu, camera, target, imu_noise, options, float(initial_time_offset), first.start_poses
    )
    problem.warnings += noise_warnings
    problem.readout_given = first.line_delay * camera.height
    est = initial_estimate(problem, T_guess, float(initial_time_offset))
    problem.others = [_initial_other(problem, est, index, other) for index, other in enumerate(others, start=1)]
    joint = task == "joint"
    g, solution, est, iterations = solve_rounds(problem, est, joint)
    g, solution, est, more, measured = reweighted_solve(problem, g, solution, est, joint)
    problem.noise_factors = measured_noise(problem, g, solution.values, measured)
    problem.imu_noise_scale *= problem.noise_factors[1]  # the weight's scale times what remains at the solution
    problem.warnings += span_warnings(problem, g) + gap_warnings(g.state_times)
    problem.warnings += imu_noise_warning(problem.imu_noise_scale, imu_noise, options.noise_weighting)
    marginals = solution_marginals(problem, g, solution.values, joint, est.imu_theta is not None)
    problem.warnings += imu_model_warnings(marginals.imu_model)
    result = first_camera_result(task, problem, g, solution, est, iterations + more, start, marginals)
    result = replace(result, frame_log=first_frame_log(frames, every, problem, g, result.reprojection_frames))
    results = [result] + [
        other_camera_result(task, problem, g, solution, est, entry, given, result, marginals)
        for entry, given in zip(g.others, others, strict=True)
    ]
    cameras = [first, *others]
    sigmas = unobserved(
        {c.name: r for c, r in zip(cameras, results, strict=True)}, {c.name: c.camera.height for c in cameras}
    )
    if not sigmas:
        return results
    again = run_visual_inertial(
        task, first, imu, target, imu_noise, replace(options, rolling_shutter=False), start, others
    )
    note = unobserved_warning(sigmas, {c.name: c.line_delay for c in cameras})
    return [replace(again[0], warnings=[note, *again[0].warnings]), *again[1:]]


def _initial_other(problem: ViProblem, est: ViEstimate, index: int, given: CameraInput) -> OtherCamera:
    """Another camera's views, PnP poses and closed-form guesses (``vical.calib.solve.rig``)."""
    opts = problem.options
    other = prepare_other(
        given.name, index, given.observations[:: opts.frame_stride], given.camera, problem.target,
        problem.t0_ns, opts.pixel_sigma, given.initial_T_cam_imu, given.start_poses, opts.rolling_shutter,
    )  # fmt: skip
    other.readout = other.readout_given = given.line_delay * given.camera.height
    initialise_other(
        other, problem.frame_times, problem.T_target_cam, est.T_cam_imu, (problem.t_imu, problem.gyro),
        opts.max_time_offset, float(given.initial_time_offset), opts.estimate_time_offset,
    )  # fmt: skip
    other.tau0 -= row_centre(opts) * other.readout_given  # its PnP poses time its middle rows
    return other

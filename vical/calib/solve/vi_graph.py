"""The camera-IMU factor graph: its states, IMU, corner and prior factors, the solve in rounds and the sensors'
reweighting by their measured noise (``vical.calib.solve.variance``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from vical.calib.errors import CalibrationError
from vical.calib.solve.corner_factors import CornerFactors, CornerKeys
from vical.calib.solve.corner_noise import MIN_PIXEL_SIGMA
from vical.calib.solve.imu_integration import interpolate, preintegrate, preintegration_params, segments_between
from vical.calib.solve.imu_intrinsics import IntervalReadings, IntrinsicImuFactor, prior_sigmas
from vical.calib.solve.rig import OtherCamera, pair
from vical.calib.solve.solver import optimize
from vical.calib.solve.variance import used_dof, variance_factor
from vical.calib.solve.vi_problem import (
    ACCEL_BIAS_PRIOR_SIGMA,
    CLUSTER_NS,
    D_KEY,
    E_KEY,
    G_KEY,
    GYRO_BIAS_PRIOR_SIGMA,
    I_KEY,
    IMU_RESIDUAL_DIM,
    K_KEY,
    L_KEY,
    MAX_REWEIGHTS,
    MAX_ROUNDS,
    READOUT_PRIOR_SIGMA,
    RECENTRE_OFFSET,
    REWEIGHT_EXPONENT_DOWN,
    REWEIGHT_EXPONENT_UP,
    REWEIGHT_TOLERANCE,
    ViEstimate,
    ViProblem,
    row_centre,
    state_key,
)
from vical.geometry import CameraModel, invert_transform


# ---------------------------------------------------------------------------------------- graph
@dataclass
class ViGraph:
    graph: gtsam.NonlinearFactorGraph
    values: gtsam.Values
    states: list[int]  # indices into problem.frame_ids of the frames that got a state
    imu_factors: list  # (i, factor, dt) per IMU factor
    state_times: np.ndarray  # (S,) [s] IMU clock
    corners: CornerFactors
    first_corner_factor: int  # index in the graph of the first corner factor (the IMU factors come first)
    # per other camera: (camera, its corner factors, their states, their recording frame indices)
    others: list[tuple[OtherCamera, CornerFactors, np.ndarray, np.ndarray]] = field(default_factory=list)
    factor_states: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # state of each factor, -1: none
    state_windows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # (S,) ``_time_windows``


def anchor(tau0: float, readout: float, options) -> float:
    """[s] from a camera's stamps to its states' times: its time offset (row 0's) plus the readout up to
    ``row_centre``'s row."""
    return tau0 + row_centre(options) * readout


def _states_inside_imu(problem: ViProblem, est: ViEstimate) -> list[int]:
    s = problem.frame_times + anchor(est.tau0, est.readout, problem.options)
    inside = np.flatnonzero((s >= problem.t_imu[0]) & (s <= problem.t_imu[-1]))
    if len(inside) < 3:
        raise CalibrationError(
            f"only {len(inside)} frames with a target pose fall inside the IMU time span after the time offset "
            f"({est.tau0 * 1e3:.1f} ms); the camera and IMU recordings barely overlap"
        )
    return inside.tolist()


def _insert_states(values: gtsam.Values, problem: ViProblem, states: list[int], est: ViEstimate) -> np.ndarray:
    """Initial IMU poses, velocities (finite differences), biases; returns the state times (S,) [s]."""
    T_imu = np.array([problem.T_target_cam[k] @ est.T_cam_imu for k in states])
    times = problem.frame_times[states] + anchor(est.tau0, est.readout, problem.options)
    vel = np.gradient(T_imu[:, :3, 3], times, axis=0) if len(states) > 1 else np.zeros((1, 3))
    bias = gtsam.imuBias.ConstantBias(est.accel_bias, est.gyro_bias)
    for n, T in enumerate(T_imu):
        values.insert(state_key("x", n), gtsam.Pose3(T))
        values.insert(state_key("v", n), vel[n])
        values.insert(state_key("b", n), bias)
    f = interpolate(problem.t_imu, problem.accel, times)
    g_dir = -np.mean(np.einsum("nij,nj->ni", T_imu[:, :3, :3], f), axis=0)
    values.insert(G_KEY, gtsam.Unit3(g_dir / np.linalg.norm(g_dir)))
    return times


def _add_imu_factors(graph: gtsam.NonlinearFactorGraph, problem: ViProblem, times: np.ndarray, est: ViEstimate) -> list:
    params = preintegration_params(problem.noise)
    bias = gtsam.imuBias.ConstantBias(est.accel_bias, est.gyro_bias)
    if est.imu_theta is not None:
        return _add_intrinsic_imu_factors(graph, problem, times, params, bias)
    factors = []
    for n, segments in enumerate(segments_between(problem.t_imu, problem.gyro, problem.accel, times)):
        pim = preintegrate(params, bias, segments)
        f = gtsam.CombinedImuFactorWithGravityDirection(
            state_key("x", n), state_key("v", n), state_key("x", n + 1), state_key("v", n + 1),
            state_key("b", n), state_key("b", n + 1), G_KEY, pim, problem.options.gravity_magnitude,
        )  # fmt: skip
        graph.add(f)
        factors.append((n, f, times[n + 1] - times[n]))
    _add_bias_prior(graph, bias)
    return factors


def _add_bias_prior(graph: gtsam.NonlinearFactorGraph, bias: gtsam.imuBias.ConstantBias) -> None:
    sigmas = np.r_[np.full(3, ACCEL_BIAS_PRIOR_SIGMA), np.full(3, GYRO_BIAS_PRIOR_SIGMA)]
    graph.add(gtsam.PriorFactorConstantBias(state_key("b", 0), bias, gtsam.noiseModel.Diagonal.Sigmas(sigmas)))


def _add_intrinsic_imu_factors(graph, problem: ViProblem, times: np.ndarray, params, bias) -> list:
    """IMU factors that also take the intrinsics ``I_KEY``, a weak prior on them and on the first bias."""
    factors = []
    for n in range(len(times) - 1):
        readings = IntervalReadings(problem.t_imu, problem.gyro, problem.accel, times[n], times[n + 1])
        keys = [
            state_key("x", n),
            state_key("v", n),
            state_key("x", n + 1),
            state_key("v", n + 1),
            state_key("b", n),
            state_key("b", n + 1),
            G_KEY,
        ]
        f = IntrinsicImuFactor(keys, I_KEY, readings, params, bias, problem.options.gravity_magnitude)
        graph.add(f.factor)
        factors.append((n, f, times[n + 1] - times[n]))
    opts = problem.options
    sigmas = gtsam.noiseModel.Diagonal.Sigmas(prior_sigmas(opts.g_sensitivity))
    graph.add(gtsam.PriorFactorVector(I_KEY, opts.initial_imu_theta(), sigmas))
    _add_bias_prior(graph, bias)
    return factors


def _corner_factors(problem: ViProblem, states: list[int], times: np.ndarray, est: ViEstimate, joint: bool):
    """The corner factors of the states' frames (``vical.calib.solve.corner_factors``)."""
    opts = problem.options
    with_offset = opts.estimate_time_offset
    moving = with_offset or opts.rolling_shutter or est.readout != 0.0
    keys = CornerKeys(
        poses=[state_key("x", n) for n in range(len(states))],
        velocities=[state_key("v", n) for n in range(len(states))] if moving else None,
        omegas=interpolate(problem.t_imu, problem.gyro, times) - est.gyro_bias if moving else None,
        extrinsic=E_KEY,
        delta=D_KEY if with_offset else None,
        camera=K_KEY if joint else None,
        readout=L_KEY if opts.rolling_shutter else None,
    )
    observations = [problem.observations[problem.frame_ids[k]] for k in states]
    return CornerFactors(
        observations, problem.camera, keys, problem.sigma_px, opts.huber_k, est.readout, row_centre(opts)
    )


def _add_readout(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, key: int, readout: float, given: float):
    """A camera's readout variable at ``readout`` [s], with its prior at the ``given`` one (``READOUT_PRIOR_SIGMA``)."""
    values.insert(key, np.array([readout]))
    graph.add(gtsam.PriorFactorVector(key, np.array([given]), gtsam.noiseModel.Isotropic.Sigma(1, READOUT_PRIOR_SIGMA)))


def _build(problem: ViProblem, est: ViEstimate, joint: bool) -> ViGraph:
    states = _states_inside_imu(problem, est)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    values.insert(E_KEY, gtsam.Pose3(invert_transform(est.T_cam_imu)))
    if problem.options.estimate_time_offset:
        values.insert(D_KEY, np.zeros(1))
    if joint:
        values.insert(K_KEY, problem.camera.parameters)
    if est.imu_theta is not None:
        values.insert(I_KEY, est.imu_theta)
    times = _insert_states(values, problem, states, est)
    imu_factors = _add_imu_factors(graph, problem, times, est)
    if problem.options.rolling_shutter:
        _add_readout(graph, values, L_KEY, est.readout, problem.readout_given)
    corners = _corner_factors(problem, states, times, est, joint)
    first_corner_factor = graph.size()
    for factor in corners.factors():
        graph.add(factor)
    priors = first_corner_factor - len(imu_factors)  # the first bias's (and the IMU intrinsics')
    factor_states = [*range(len(imu_factors)), *[-1] * priors, *range(len(states))]
    others = []
    for other in problem.others:
        factors, paired, frames = _other_corner_factors(problem, other, states, times, est, joint, values)
        for factor in factors.factors():
            graph.add(factor)
        factor_states += paired.tolist()
        if problem.options.rolling_shutter:
            _add_readout(graph, values, state_key("l", other.index), other.readout, other.readout_given)
            factor_states.append(-1)
        if not problem.options.estimate_time_offset:  # its offset stays at the guess
            graph.add(
                gtsam.PriorFactorVector(
                    state_key("d", other.index), np.zeros(1), gtsam.noiseModel.Isotropic.Sigma(1, 1e-9)
                )
            )
            factor_states.append(-1)
        others.append((other, factors, paired, np.array([other.observations[j].index for j in frames], np.int64)))
    return ViGraph(
        graph, values, states, imu_factors, times, corners, first_corner_factor, others, np.array(factor_states),
        _time_windows(problem, states),
    )  # fmt: skip


def _time_windows(problem: ViProblem, states: list[int]) -> np.ndarray:
    """The time window (``CLUSTER_NS``) of each state, counted from the first state's frame on the camera's own clock.

    Integer timestamps: frames at a steady rate fall exactly on window edges, where float seconds
    shifted by the time offset land on either side depending on the last bit (and with them the
    robust 1-sigma, by 10 % and more).
    """
    t_ns = np.array([problem.observations[problem.frame_ids[k]].t_ns for k in states], dtype=np.int64)
    return (t_ns - t_ns[0]) // CLUSTER_NS


def _other_corner_factors(
    problem: ViProblem, other: OtherCamera, states: list[int], times: np.ndarray, est: ViEstimate, joint: bool, values
) -> tuple[CornerFactors, np.ndarray, np.ndarray]:
    """Another camera's variables and corner factors on the states of its simultaneous first-camera frames."""
    values.insert(state_key("e", other.index), gtsam.Pose3(invert_transform(other.T_cam_imu)))
    values.insert(state_key("d", other.index), np.zeros(1))
    if joint:
        values.insert(state_key("k", other.index), other.camera.parameters)
    paired, frames = pair(problem.frame_times[states], other.frame_times)
    if len(paired) < 3:
        raise CalibrationError(
            f"{other.name}: only {len(paired)} of its views were taken with a view of the first camera inside the IMU "
            "span; the cameras of a rig are calibrated together when they are triggered together"
        )
    keys = CornerKeys(
        poses=[state_key("x", n) for n in paired],
        velocities=[state_key("v", n) for n in paired],
        omegas=interpolate(problem.t_imu, problem.gyro, times[paired]) - est.gyro_bias,
        extrinsic=state_key("e", other.index),
        delta=state_key("d", other.index),
        camera=state_key("k", other.index) if joint else None,
        shifts=other.frame_times[frames] + anchor(other.tau0, other.readout, problem.options) - times[paired],
        readout=state_key("l", other.index) if problem.options.rolling_shutter else None,
    )
    observations = [other.observations[j] for j in frames]
    factors = CornerFactors(
        observations, other.camera, keys, other.sigma_px, problem.options.huber_k, other.readout,
        row_centre(problem.options),
    )  # fmt: skip
    return factors, paired, frames


# ---------------------------------------------------------------------------------------- solve
def _camera_of(values: gtsam.Values, problem: ViProblem, joint: bool) -> CameraModel:
    return problem.camera.with_parameters(values.atVector(K_KEY)) if joint else problem.camera


def _timing(values: gtsam.Values, index: int, tau0: float, readout: float, options) -> tuple[float, float]:
    """Camera ``index``'s time offset (row 0's) [s] and readout [s] from the solution, built at ``tau0`` and
    ``readout``: the states' time (``anchor``) plus the correction, less the new readout up to the centre row."""
    delta_key, readout_key = state_key("d", index), state_key("l", index)
    delta = float(values.atVector(delta_key)[0]) if values.exists(delta_key) else 0.0
    new_readout = float(values.atVector(readout_key)[0]) if values.exists(readout_key) else readout
    return anchor(tau0, readout, options) + delta - row_centre(options) * new_readout, new_readout


def _estimate_of(values: gtsam.Values, est: ViEstimate, options) -> ViEstimate:
    bias = values.atConstantBias(state_key("b", 0))
    T_cam_imu = invert_transform(values.atPose3(E_KEY).matrix())
    tau, readout = _timing(values, 0, est.tau0, est.readout, options)
    theta = np.asarray(values.atVector(I_KEY)) if values.exists(I_KEY) else None
    return ViEstimate(T_cam_imu, tau, np.asarray(bias.gyroscope()), np.asarray(bias.accelerometer()), theta, readout)


def solve_rounds(problem: ViProblem, est: ViEstimate, joint: bool, start: gtsam.Values | None = None):
    """Build and solve, re-centring the states on the new offset while the in-graph correction is large.

    ``start``: the last solution of this problem (before its sensors were reweighted) to begin from
    (``_warm_start``), ``est`` its estimate; None: the closed-form start the graph is built with.
    """
    iterations = 0
    for _ in range(MAX_ROUNDS):
        g = _build(problem, est, joint)
        initial = g.values if start is None else _warm_start(g.values, start)
        start = None
        solution = optimize(g.graph, initial, problem.options.max_iterations, "camera-IMU calibration")
        iterations += solution.iterations
        new = _estimate_of(solution.values, est, problem.options)
        # How far the states' times moved: the middle row's correction (row 0's without a readout variable).
        correction = anchor(new.tau0, new.readout, problem.options) - anchor(est.tau0, est.readout, problem.options)
        problem.camera = _camera_of(solution.values, problem, joint)
        for other in problem.others:
            _update_other(other, solution.values, joint, problem.options)
        if not problem.options.estimate_time_offset or abs(correction) < RECENTRE_OFFSET:
            return g, solution, new, iterations
        est = new
    problem.warnings.append(f"the time offset moved by {correction * 1e3:.2f} ms in the last round")
    return g, solution, new, iterations


def _warm_start(values: gtsam.Values, start: gtsam.Values) -> gtsam.Values:
    """``start``'s values with every camera's time-offset correction at 0 (the estimate the graph was built from holds
    it) where the graph has exactly ``start``'s variables, else ``values``. A re-solve after reweighting then takes
    two or three iterations, not a whole solve's (measured: 2 where the closed-form start took 4)."""
    keys = list(values.keys())
    if sorted(keys) != sorted(start.keys()):
        return values
    warm = gtsam.Values(start)
    for key in keys:
        if gtsam.Symbol(key).chr() == ord("d"):
            warm.update(key, np.zeros(1))
    return warm


def _update_other(other: OtherCamera, values: gtsam.Values, joint: bool, options) -> None:
    """Another camera's estimates from the solution: its extrinsic, offset (the correction folded in), readout,
    camera."""
    other.T_cam_imu = invert_transform(values.atPose3(state_key("e", other.index)).matrix())
    other.tau0, other.readout = _timing(values, other.index, other.tau0, other.readout, options)
    if joint:
        other.camera = other.camera.with_parameters(values.atVector(state_key("k", other.index)))


def _noise_factors(g: ViGraph, values: gtsam.Values) -> tuple[float, float]:
    """(cameras, IMU): the sensors' a posteriori noise over the noise they were weighted with."""
    linear = g.graph.linearize(values)
    ordering = gtsam.Ordering.ColamdGaussianFactorGraph(linear)
    imu = range(len(g.imu_factors))
    corners = np.flatnonzero(g.factor_states >= 0)
    corners = corners[corners >= g.first_corner_factor]
    chi2_imu = 2.0 * sum(f.error(values) for _, f, _ in g.imu_factors)
    s2_imu = variance_factor(chi2_imu, IMU_RESIDUAL_DIM * len(imu), used_dof(linear, imu, ordering))
    all_corners = [g.corners] + [entry[1] for entry in g.others]
    chi2 = sum(c.chi2(values) for c in all_corners)
    s2_camera = variance_factor(chi2, 2 * sum(len(c.points) for c in all_corners), used_dof(linear, corners, ordering))
    return float(np.sqrt(s2_camera)), float(np.sqrt(s2_imu))


def reweighted_solve(problem: ViProblem, g: ViGraph, solution, est: ViEstimate, joint: bool):
    """Weight each sensor by the noise its residuals show, solving again while a weight is off (``_noise_factors``),
    as ``ViOptions.noise_weighting`` says: not at all (``declared``), freely (``measured``), or with the IMU never
    weighted below its declared densities (``declared-or-less``).

    Noise-free corners (the corner noise at its floor) leave nothing to weigh: any weights give the
    exact solution, and the IMU's own model error would take over.

    Returns the graph, solution, estimate, iterations and the noise factors measured at that solution
    (None where the last solve came after the last measurement).
    """
    iterations = 0
    scheme = problem.options.noise_weighting
    if problem.sigma_px <= MIN_PIXEL_SIGMA or scheme == "declared":
        return g, solution, est, iterations, None
    measured = None
    for _ in range(MAX_REWEIGHTS):
        s_camera, s_imu = measured = _noise_factors(g, solution.values)
        if not all(np.isfinite([s_camera, s_imu])):
            break
        s_camera = max(s_camera, MIN_PIXEL_SIGMA / problem.sigma_px)  # the corner noise keeps its floor
        if scheme == "declared-or-less" and s_imu > 1 and problem.imu_noise_scale >= 1:
            s_imu = 1.0  # at its declared weight, and the residuals ask for less: it stays
        if max(s_camera, 1 / s_camera, s_imu, 1 / s_imu) <= REWEIGHT_TOLERANCE:
            break
        # A factor measured at the old weights falls short of the truth (the redundancy is judged at those
        # weights): measured 0.33 and 0.18 for settings 10x and 100x the truth, 5.0 for 0.1x. Steps of
        # s^2 (s < 1) and s^1.5 (s > 1) reach the truth in two or three rounds; an overshoot comes back.
        step = s_imu ** (REWEIGHT_EXPONENT_DOWN if s_imu < 1 else REWEIGHT_EXPONENT_UP)
        if scheme == "declared-or-less":
            step = min(step, 1.0 / problem.imu_noise_scale)
        problem.sigma_px *= s_camera
        for other in problem.others:
            other.sigma_px *= s_camera
        problem.noise = problem.noise.scaled(step)
        problem.imu_noise_scale *= step
        g, solution, est, more = solve_rounds(problem, est, joint, solution.values)
        iterations += more
        measured = None
    return g, solution, est, iterations, measured


def measured_noise(
    problem: ViProblem, g: ViGraph, values: gtsam.Values, measured: tuple[float, float] | None
) -> tuple[float, float]:
    """(cameras, IMU) noise at the solution over their weights (``measured`` when already known there); 1 where it
    cannot be measured (no redundancy)."""
    if problem.sigma_px <= MIN_PIXEL_SIGMA:  # noise-free corners: nothing to measure against
        return 1.0, 1.0
    factors = _noise_factors(g, values) if measured is None else measured
    return tuple(float(f) if np.isfinite(f) and f > 0 else 1.0 for f in factors)


def variance_scale(problem: ViProblem, g: ViGraph, num_factors: int) -> np.ndarray:
    """(F,) each factor's measured variance over the variance it was weighted with (priors: 1)."""
    s_camera, s_imu = problem.noise_factors
    scale = np.ones(num_factors)
    scale[: len(g.imu_factors)] = s_imu**2
    corners = np.flatnonzero(g.factor_states[:num_factors] >= 0)
    scale[corners[corners >= g.first_corner_factor]] = s_camera**2
    return scale

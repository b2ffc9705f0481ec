"""Camera-IMU calibration in one factor graph: extrinsic, time offset, biases, and optionally intrinsics.

Layout (navigation frame = target frame, so no gauge prior is needed):

- per used frame ``i``: IMU state ``X_i`` (``Pose3`` ``T_target_imu`` at IMU time
  ``t_cam_i + tau0``), velocity ``V_i`` [m/s] (target frame), bias ``B_i``;
- shared: ``E`` = ``T_imu_cam`` (``Pose3``), gravity direction ``G`` (``Unit3``, target frame),
  time-offset correction ``D`` [s] (``tau = tau0 + D``), and in the joint task the camera
  parameters ``K`` (``CameraModel.parameters``, 8 or 6);
- a rig's other cameras ``c`` (``vical.calib.rig``): their own ``E_c``, ``D_c`` (and ``K_c``); their frames
  join the states of the first camera's simultaneous frames;
- factors: one corner factor per frame on ``(X_i, V_i, E, D[, K])``, which projects the known
  target points from the pose at the exposure instant ``X_i Exp([omega_i; R_i^T V_i] D) E``
  (``vical.calib.corner_factors``), ``CombinedImuFactorWithGravityDirection`` between consecutive
  states (rotation-compensated midpoint preintegration), a weak prior on the first bias;
- with ``imu_model="scale-misalignment"`` the IMU intrinsics ``I`` (scale, misalignment, optionally
  the gyro's g-sensitivity) are a variable of every IMU factor (``vical.calib.imu_intrinsics``), with
  a weak prior; known intrinsics (``ViOptions.imu_intrinsics``) otherwise correct the readings.

Initialisation: PnP poses with the (known or intrinsically calibrated) camera; time offset,
``R_cam_imu`` and gyro bias in closed form (``time_alignment``); translation from the guess;
velocities by finite differences; gravity from the mean specific force.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np

from vical.calib.checks import check_imu_noise, check_memory
from vical.calib.corner_factors import CornerFactors, CornerKeys
from vical.calib.errors import CalibrationError, CalibrationSettingError
from vical.calib.frame_log import FrameLog, build_frame_log, left_out
from vical.calib.imu_integration import interpolate, midpoint_segments, preintegrate, preintegration_params
from vical.calib.imu_intrinsics import IntervalReadings, IntrinsicImuFactor, check_excitation, prior_sigmas
from vical.calib.imu_intrinsics import check_model as check_imu_model
from vical.calib.initialization import MIN_INIT_CORNERS, frame_poses
from vical.calib.intrinsics import check_model, estimated_pixel_sigma, intrinsic_names
from vical.calib.nominal import nominal_T_cam_imu
from vical.calib.observations import FrameObservation
from vical.calib.outliers import reject_outliers
from vical.calib.result import CalibrationResult, FramePoses, ImuResiduals, ResidualStats, TimeOffsetTrace
from vical.calib.rig import OtherCamera, initialise_other, pair, prepare_other
from vical.calib.robust_covariance import sandwich_covariances, widen
from vical.calib.solver import covariance_or_unobservable, optimize
from vical.calib.time_alignment import align, increment_mismatch, rotation_increments
from vical.calib.uncertainty import correlation_warnings, correlations, unobservable_warnings, weak_parameters
from vical.calib.variance import used_dof, variance_factor
from vical.data import CameraFrames, ImuNoise, ImuSamples, Target, seconds_since
from vical.data.imu_model import ImuIntrinsics
from vical.geometry import CameraModel, invert_transform, make_transform, skew

GRAVITY_MAGNITUDE = 9.81  # [m/s^2]
GYRO_BIAS_PRIOR_SIGMA = 0.1  # [rad/s] weak prior on the first gyro bias (keeps short recordings well posed)
ACCEL_BIAS_PRIOR_SIGMA = 1.0  # [m/s^2] weak prior on the first accelerometer bias
MIN_PIXEL_SIGMA = 0.01  # [px] floor of the estimated corner noise (noise-free data would weight pixels infinitely)
RECENTRE_OFFSET = 1e-3  # [s] re-linearise the states at the new offset when the in-graph correction exceeds this
MAX_ROUNDS = 3
# Noise levels (vical.calib.variance): a sensor whose residuals say its noise is off by more than this
# factor is reweighted and the problem solved again, at most MAX_REWEIGHTS times.
REWEIGHT_TOLERANCE = 1.15
MAX_REWEIGHTS = 3
REWEIGHT_EXPONENT_DOWN, REWEIGHT_EXPONENT_UP = 2.0, 1.5
IMU_NOISE_WARNING = 2.0  # tell the user when the IMU's noise is off by more than this factor
# How the sensors' measured noise enters the solve (docs/calibration.md, "Weighting the sensors"); the uncertainty
# always uses the noise levels the residuals show at the solution. "declared": the IMU weighted by its declared
# densities, the corners by the noise PnP measures; "measured": every sensor reweighted by its measured noise;
# "declared-or-less": reweighted, but the IMU never below the weight its declared densities give (an inflated
# imu.yaml is corrected, an excess over the datasheet, which is seldom white, is not).
NOISE_WEIGHTINGS = ("declared", "measured", "declared-or-less")
CLUSTER_NS = 500_000_000  # [ns] time windows of the cluster-robust covariance
WIDENING_WARNING = 2.0  # tell the user when a 1-sigma was widened by more than this factor
IMU_RESIDUAL_DIM = 15  # per CombinedImuFactor: rotation, velocity, position, accel and gyro bias changes
MIN_GAP_WARNING = 0.5  # [s] a stretch without target views this long (and ...
GAP_WARNING_FACTOR = 5.0  # ... this many typical frame intervals) is reported
TRACE_HALF_WIDTH = 0.05  # [s] the report's time-offset plot shows the mismatch this far either side of the estimate
TRACE_POINTS = 201

E_KEY, G_KEY, D_KEY, K_KEY, I_KEY = (gtsam.symbol(c, 0) for c in "egdki")
EXTRINSIC_NAMES = ["rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "time_offset"]
BIAS_NAMES = ["ba_x", "ba_y", "ba_z", "bg_x", "bg_y", "bg_z"]  # GTSAM's ConstantBias order: accel, then gyro


def _key(c: str, i: int) -> int:
    return gtsam.symbol(c, i)


@dataclass(frozen=True)
class ViOptions:
    """Settings of the camera-IMU solve.

    Attributes:
        estimate_time_offset: estimate the time offset (else it stays at the initial value).
        max_time_offset: [s] half-width of the closed-form time-offset scan around the guess.
        pixel_sigma: [px] corner noise; None estimates it from the PnP residuals.
        huber_k: Huber kernel width in sigmas for the projection factors (None: least squares).
        max_iterations: Levenberg-Marquardt iterations per round.
        gravity_magnitude: [m/s^2] local gravity.
        frame_stride: use every ``frame_stride``-th frame with a target view (1: all); thins long or
            high-rate recordings (the accuracy cost is measured in docs/calibration.md).
        memory_limit_mb: [MB] a recording whose solve would need more is refused before solving,
            with the stride that fits (``vical.calib.checks``).
        imu_model: ``calibrated`` (the readings, corrected by ``imu_intrinsics`` when given, are
            exact up to noise and bias) or ``scale-misalignment`` (estimate the IMU intrinsics,
            starting from ``imu_intrinsics``; Kalibr's model of that name).
        g_sensitivity: with ``scale-misalignment``, also estimate the gyro's g-sensitivity.
        imu_intrinsics: the IMU's known intrinsics (e.g. from Kalibr's imu.yaml), or None (identity).
    """

    estimate_time_offset: bool = True
    max_time_offset: float = 0.1
    pixel_sigma: float | None = None
    huber_k: float | None = None
    max_iterations: int = 50
    gravity_magnitude: float = GRAVITY_MAGNITUDE
    frame_stride: int = 1
    memory_limit_mb: float = 4000.0
    imu_model: str = "calibrated"
    g_sensitivity: bool = False
    imu_intrinsics: ImuIntrinsics | None = None
    noise_weighting: str = "declared-or-less"

    def __post_init__(self) -> None:
        checks = {
            "max_time_offset": (self.max_time_offset, "a number >= 0 [s]", self.max_time_offset >= 0),
            "pixel_sigma": (
                self.pixel_sigma,
                "None or a number > 0 [px]",
                self.pixel_sigma is None or self.pixel_sigma > 0,
            ),
            "huber_k": (self.huber_k, "None or a number > 0 [sigmas]", self.huber_k is None or self.huber_k > 0),
            "max_iterations": (self.max_iterations, "an integer >= 1", self.max_iterations >= 1),
            "gravity_magnitude": (self.gravity_magnitude, "a number > 0 [m/s^2]", self.gravity_magnitude > 0),
            "frame_stride": (
                self.frame_stride,
                "an integer >= 1",
                isinstance(self.frame_stride, int) and self.frame_stride >= 1,
            ),
            "memory_limit_mb": (self.memory_limit_mb, "a number > 0 [MB]", self.memory_limit_mb > 0),
        }
        for name, (value, allowed, ok) in checks.items():
            if not ok:
                raise CalibrationError(f"calibration option {name} must be {allowed}, got {value!r}")
        if self.noise_weighting not in NOISE_WEIGHTINGS:
            allowed = list(NOISE_WEIGHTINGS)
            raise CalibrationError(
                f"calibration option noise_weighting must be one of {allowed}, got {self.noise_weighting!r}"
            )
        check_imu_model(self.imu_model, self.g_sensitivity)

    @property
    def estimate_imu_intrinsics(self) -> bool:
        return self.imu_model == "scale-misalignment"

    def initial_imu_theta(self) -> np.ndarray:
        """The intrinsics' starting parameters (``ImuIntrinsics.vector``)."""
        return (self.imu_intrinsics or ImuIntrinsics()).vector(self.g_sensitivity)


@dataclass
class _Problem:
    """Everything the graph is built from (times in seconds since the recording start)."""

    camera: CameraModel
    target: Target
    observations: list[FrameObservation]
    frame_ids: list[int]  # indices into observations of the frames that get a state
    frame_times: np.ndarray  # (F,) [s] camera clock
    T_target_cam: np.ndarray  # (F, 4, 4) initial camera poses
    t_imu: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    noise: ImuNoise
    options: ViOptions
    t0_ns: int
    sigma_px: float = 1.0
    imu_noise_scale: float = 1.0  # a posteriori / declared IMU noise (the variance factors' product)
    # (cameras, IMU) noise the residuals show at the final solution over the noise they were weighted with
    noise_factors: tuple[float, float] = (1.0, 1.0)
    warnings: list[str] = field(default_factory=list)
    others: list[OtherCamera] = field(default_factory=list)  # a rig's other cameras
    outliers: list[int] = field(default_factory=list)  # frame indices of the frames dropped as outliers


@dataclass
class _Estimate:
    """The current extrinsic estimate (input to a round, output of it)."""

    T_cam_imu: np.ndarray
    tau0: float
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    imu_theta: np.ndarray | None = None  # IMU intrinsics (ImuIntrinsics.vector) when estimated


# ---------------------------------------------------------------------------------------- preparation
def _check_overlap(imu: ImuSamples, frame_t_ns: np.ndarray, t0_ns: int, offset_guess: float) -> None:
    """Raise unless the frames, moved to IMU time by the offset guess [s], overlap the IMU samples."""
    if len(imu) < 2:
        raise CalibrationError("the recording has fewer than 2 IMU samples; camera-IMU calibration needs the IMU")
    shift = round(offset_guess * 1e9)
    lo, hi = frame_t_ns.min() + shift, frame_t_ns.max() + shift
    if hi < imu.t[0] or lo > imu.t[-1]:
        span = seconds_since(np.array([lo, hi, imu.t[0], imu.t[-1]]), t0_ns)
        raise CalibrationSettingError(
            f"camera frames span {span[0]:.3f}..{span[1]:.3f} s and IMU samples {span[2]:.3f}..{span[3]:.3f} s "
            f"(relative to the recording start, frames moved by the time-offset guess {offset_guess:g} s): they do "
            "not overlap; check that both streams use the same clock or give the offset as the initial guess ({fix})",
            "initial_time_offset", None, None,
        )  # fmt: skip


def _prepare(
    frames_obs: list[FrameObservation],
    imu: ImuSamples,
    camera: CameraModel,
    target: Target,
    noise: ImuNoise,
    options: ViOptions,
    offset_guess: float,
) -> _Problem:
    frame_t_ns = np.array([o.t_ns for o in frames_obs], dtype=np.int64)
    t0_ns = int(min(imu.t[0], frame_t_ns.min())) if len(imu) else int(frame_t_ns.min())
    _check_overlap(imu, frame_t_ns, t0_ns, offset_guess)
    min_corners = min(MIN_INIT_CORNERS, target.num_points)
    initial = {k: T for k, (T, _) in frame_poses(camera, frames_obs, min_corners).items()}
    rejection = reject_outliers(camera, frames_obs, initial, min_corners)
    frames_obs, poses = rejection.observations, rejection.poses
    if len(poses) < 3:
        raise CalibrationError(
            f"only {len(poses)} frames have a usable target pose; camera-IMU calibration needs a sequence of views"
        )
    ids = sorted(poses)
    residuals = np.concatenate([frames_obs[k].residuals(camera, poses[k]) for k in ids])
    sigma = options.pixel_sigma
    if sigma is None:
        sigma = max(estimated_pixel_sigma(residuals, 6 * len(ids)), MIN_PIXEL_SIGMA)
    gyro, accel = imu.gyro, imu.accel
    if options.estimate_imu_intrinsics:
        check_excitation(gyro, accel)
    elif options.imu_intrinsics is not None:
        gyro, accel = options.imu_intrinsics.correct(gyro, accel)
    return _Problem(
        camera=camera,
        target=target,
        observations=frames_obs,
        frame_ids=ids,
        frame_times=seconds_since(frame_t_ns[ids], t0_ns),
        T_target_cam=np.array([invert_transform(poses[k]) for k in ids]),
        t_imu=seconds_since(imu.t, t0_ns),
        gyro=gyro,
        accel=accel,
        noise=noise,
        options=options,
        t0_ns=t0_ns,
        sigma_px=float(sigma),
        warnings=list(rejection.warnings),
        outliers=list(rejection.dropped),
    )


def _initial_estimate(problem: _Problem, T_guess: np.ndarray, tau_guess: float) -> _Estimate:
    """Closed-form time offset, rotation and gyro bias; translation from the guess."""
    inc = rotation_increments(problem.frame_times, problem.T_target_cam[:, :3, :3])
    opts = problem.options
    alignment = align(problem.t_imu, problem.gyro, inc, opts.max_time_offset, tau_guess, opts.estimate_time_offset)
    theta = opts.initial_imu_theta() if opts.estimate_imu_intrinsics else None
    return _Estimate(
        make_transform(alignment.R_cam_imu, T_guess[:3, 3]), alignment.time_offset, alignment.gyro_bias, np.zeros(3),
        theta,
    )  # fmt: skip


# ---------------------------------------------------------------------------------------- graph
@dataclass
class _Graph:
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


def _states_inside_imu(problem: _Problem, tau0: float) -> list[int]:
    s = problem.frame_times + tau0
    inside = np.flatnonzero((s >= problem.t_imu[0]) & (s <= problem.t_imu[-1]))
    if len(inside) < 3:
        raise CalibrationError(
            f"only {len(inside)} frames with a target pose fall inside the IMU time span after the time offset "
            f"({tau0 * 1e3:.1f} ms); the camera and IMU recordings barely overlap"
        )
    return inside.tolist()


def _insert_states(values: gtsam.Values, problem: _Problem, states: list[int], est: _Estimate) -> np.ndarray:
    """Initial IMU poses, velocities (finite differences), biases; returns the state times (S,) [s]."""
    T_imu = np.array([problem.T_target_cam[k] @ est.T_cam_imu for k in states])
    times = problem.frame_times[states] + est.tau0
    vel = np.gradient(T_imu[:, :3, 3], times, axis=0) if len(states) > 1 else np.zeros((1, 3))
    bias = gtsam.imuBias.ConstantBias(est.accel_bias, est.gyro_bias)
    for n, T in enumerate(T_imu):
        values.insert(_key("x", n), gtsam.Pose3(T))
        values.insert(_key("v", n), vel[n])
        values.insert(_key("b", n), bias)
    f = interpolate(problem.t_imu, problem.accel, times)
    g_dir = -np.mean(np.einsum("nij,nj->ni", T_imu[:, :3, :3], f), axis=0)
    values.insert(G_KEY, gtsam.Unit3(g_dir / np.linalg.norm(g_dir)))
    return times


def _add_imu_factors(graph: gtsam.NonlinearFactorGraph, problem: _Problem, times: np.ndarray, est: _Estimate) -> list:
    params = preintegration_params(problem.noise)
    bias = gtsam.imuBias.ConstantBias(est.accel_bias, est.gyro_bias)
    if est.imu_theta is not None:
        return _add_intrinsic_imu_factors(graph, problem, times, params, bias)
    factors = []
    for n in range(len(times) - 1):
        segments = midpoint_segments(problem.t_imu, problem.gyro, problem.accel, times[n], times[n + 1])
        pim = preintegrate(params, bias, segments)
        f = gtsam.CombinedImuFactorWithGravityDirection(
            _key("x", n), _key("v", n), _key("x", n + 1), _key("v", n + 1), _key("b", n), _key("b", n + 1),
            G_KEY, pim, problem.options.gravity_magnitude,
        )  # fmt: skip
        graph.add(f)
        factors.append((n, f, times[n + 1] - times[n]))
    _add_bias_prior(graph, bias)
    return factors


def _add_bias_prior(graph: gtsam.NonlinearFactorGraph, bias: gtsam.imuBias.ConstantBias) -> None:
    sigmas = np.r_[np.full(3, ACCEL_BIAS_PRIOR_SIGMA), np.full(3, GYRO_BIAS_PRIOR_SIGMA)]
    graph.add(gtsam.PriorFactorConstantBias(_key("b", 0), bias, gtsam.noiseModel.Diagonal.Sigmas(sigmas)))


def _add_intrinsic_imu_factors(graph, problem: _Problem, times: np.ndarray, params, bias) -> list:
    """IMU factors that also take the intrinsics ``I_KEY``, a weak prior on them and on the first bias."""
    factors = []
    for n in range(len(times) - 1):
        readings = IntervalReadings(problem.t_imu, problem.gyro, problem.accel, times[n], times[n + 1])
        keys = [_key("x", n), _key("v", n), _key("x", n + 1), _key("v", n + 1), _key("b", n), _key("b", n + 1), G_KEY]
        f = IntrinsicImuFactor(keys, I_KEY, readings, params, bias, problem.options.gravity_magnitude)
        graph.add(f.factor)
        factors.append((n, f, times[n + 1] - times[n]))
    opts = problem.options
    sigmas = gtsam.noiseModel.Diagonal.Sigmas(prior_sigmas(opts.g_sensitivity))
    graph.add(gtsam.PriorFactorVector(I_KEY, opts.initial_imu_theta(), sigmas))
    _add_bias_prior(graph, bias)
    return factors


def _corner_factors(problem: _Problem, states: list[int], times: np.ndarray, est: _Estimate, joint: bool):
    """The corner factors of the states' frames (``vical.calib.corner_factors``)."""
    with_offset = problem.options.estimate_time_offset
    keys = CornerKeys(
        poses=[_key("x", n) for n in range(len(states))],
        velocities=[_key("v", n) for n in range(len(states))] if with_offset else None,
        omegas=interpolate(problem.t_imu, problem.gyro, times) - est.gyro_bias if with_offset else None,
        extrinsic=E_KEY,
        delta=D_KEY if with_offset else None,
        camera=K_KEY if joint else None,
    )
    observations = [problem.observations[problem.frame_ids[k]] for k in states]
    return CornerFactors(observations, problem.camera, keys, problem.sigma_px, problem.options.huber_k)


def _build(problem: _Problem, est: _Estimate, joint: bool) -> _Graph:
    states = _states_inside_imu(problem, est.tau0)
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
        if not problem.options.estimate_time_offset:  # its offset stays at the guess
            graph.add(
                gtsam.PriorFactorVector(_key("d", other.index), np.zeros(1), gtsam.noiseModel.Isotropic.Sigma(1, 1e-9))
            )
            factor_states.append(-1)
        others.append((other, factors, paired, np.array([other.observations[j].index for j in frames], np.int64)))
    return _Graph(
        graph, values, states, imu_factors, times, corners, first_corner_factor, others, np.array(factor_states),
        _time_windows(problem, states),
    )  # fmt: skip


def _time_windows(problem: _Problem, states: list[int]) -> np.ndarray:
    """The time window (``CLUSTER_NS``) of each state, counted from the first state's frame on the camera's own clock.

    Integer timestamps: frames at a steady rate fall exactly on window edges, where float seconds
    shifted by the time offset land on either side depending on the last bit (and with them the
    robust 1-sigma, by 10 % and more).
    """
    t_ns = np.array([problem.observations[problem.frame_ids[k]].t_ns for k in states], dtype=np.int64)
    return (t_ns - t_ns[0]) // CLUSTER_NS


def _other_corner_factors(
    problem: _Problem, other: OtherCamera, states: list[int], times: np.ndarray, est: _Estimate, joint: bool, values
) -> tuple[CornerFactors, np.ndarray, np.ndarray]:
    """Another camera's variables and corner factors on the states of its simultaneous first-camera frames."""
    values.insert(_key("e", other.index), gtsam.Pose3(invert_transform(other.T_cam_imu)))
    values.insert(_key("d", other.index), np.zeros(1))
    if joint:
        values.insert(_key("k", other.index), other.camera.parameters)
    paired, frames = pair(problem.frame_times[states], other.frame_times)
    if len(paired) < 3:
        raise CalibrationError(
            f"{other.name}: only {len(paired)} of its views were taken with a view of the first camera inside the IMU "
            "span; the cameras of a rig are calibrated together when they are triggered together"
        )
    keys = CornerKeys(
        poses=[_key("x", n) for n in paired],
        velocities=[_key("v", n) for n in paired],
        omegas=interpolate(problem.t_imu, problem.gyro, times[paired]) - est.gyro_bias,
        extrinsic=_key("e", other.index),
        delta=_key("d", other.index),
        camera=_key("k", other.index) if joint else None,
        shifts=other.frame_times[frames] + other.tau0 - times[paired],
    )
    observations = [other.observations[j] for j in frames]
    return CornerFactors(observations, other.camera, keys, other.sigma_px, problem.options.huber_k), paired, frames


# ---------------------------------------------------------------------------------------- solve
def _camera_of(values: gtsam.Values, problem: _Problem, joint: bool) -> CameraModel:
    return problem.camera.with_parameters(values.atVector(K_KEY)) if joint else problem.camera


def _estimate_of(values: gtsam.Values, est: _Estimate) -> _Estimate:
    bias = values.atConstantBias(_key("b", 0))
    T_cam_imu = invert_transform(values.atPose3(E_KEY).matrix())
    tau = est.tau0 + (float(values.atVector(D_KEY)[0]) if values.exists(D_KEY) else 0.0)
    theta = np.asarray(values.atVector(I_KEY)) if values.exists(I_KEY) else None
    return _Estimate(T_cam_imu, tau, np.asarray(bias.gyroscope()), np.asarray(bias.accelerometer()), theta)


def _solve_rounds(problem: _Problem, est: _Estimate, joint: bool):
    """Build and solve, re-centring the states on the new offset while the in-graph correction is large."""
    iterations = 0
    for _ in range(MAX_ROUNDS):
        g = _build(problem, est, joint)
        solution = optimize(g.graph, g.values, problem.options.max_iterations, "camera-IMU calibration")
        iterations += solution.iterations
        new = _estimate_of(solution.values, est)
        correction = new.tau0 - est.tau0
        problem.camera = _camera_of(solution.values, problem, joint)
        for other in problem.others:
            _update_other(other, solution.values, joint)
        if not problem.options.estimate_time_offset or abs(correction) < RECENTRE_OFFSET:
            return g, solution, new, iterations
        est = new
    problem.warnings.append(f"the time offset moved by {correction * 1e3:.2f} ms in the last round")
    return g, solution, new, iterations


def _update_other(other: OtherCamera, values: gtsam.Values, joint: bool) -> None:
    """Another camera's estimates from the solution: its extrinsic, offset (the correction folded in), camera."""
    other.T_cam_imu = invert_transform(values.atPose3(_key("e", other.index)).matrix())
    other.tau0 += float(values.atVector(_key("d", other.index))[0])
    if joint:
        other.camera = other.camera.with_parameters(values.atVector(_key("k", other.index)))


def _noise_factors(g: _Graph, values: gtsam.Values) -> tuple[float, float]:
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


def _reweighted_solve(problem: _Problem, g: _Graph, solution, est: _Estimate, joint: bool):
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
        g, solution, est, more = _solve_rounds(problem, est, joint)
        iterations += more
        measured = None
    return g, solution, est, iterations, measured


def _measured_noise(
    problem: _Problem, g: _Graph, values: gtsam.Values, measured: tuple[float, float] | None
) -> tuple[float, float]:
    """(cameras, IMU) noise at the solution over their weights (``measured`` when already known there); 1 where it
    cannot be measured (no redundancy)."""
    if problem.sigma_px <= MIN_PIXEL_SIGMA:  # noise-free corners: nothing to measure against
        return 1.0, 1.0
    factors = _noise_factors(g, values) if measured is None else measured
    return tuple(float(f) if np.isfinite(f) and f > 0 else 1.0 for f in factors)


def _variance_scale(problem: _Problem, g: _Graph, num_factors: int) -> np.ndarray:
    """(F,) each factor's measured variance over the variance it was weighted with (priors: 1)."""
    s_camera, s_imu = problem.noise_factors
    scale = np.ones(num_factors)
    scale[: len(g.imu_factors)] = s_imu**2
    corners = np.flatnonzero(g.factor_states[:num_factors] >= 0)
    scale[corners[corners >= g.first_corner_factor]] = s_camera**2
    return scale


def _imu_noise_warning(scale: float, declared: ImuNoise, weighting: str) -> list[str]:
    """A note when the IMU's residuals show a noise ``scale`` x the ``declared`` densities, with the imu.yaml values
    that would match them."""
    if 1 / IMU_NOISE_WARNING <= scale <= IMU_NOISE_WARNING:
        return []
    side = "larger; 5-15x is common for real IMUs" if scale > 1 else "smaller: inflated densities are common"
    kept = weighting == "declared" or (weighting == "declared-or-less" and scale > 1)
    how = (
        "the estimate weighs the IMU by the declared densities, its uncertainty by the measured noise"
        if kept
        else "the solve weighted the IMU by its measured noise and the uncertainty uses it"
    )
    match = declared.scaled(scale)
    return [
        f"the IMU residuals show a noise {scale:.3g}x the declared densities ({side}); {how}. imu.yaml values that "
        f"match the residuals{' (judged at the declared weights: a large excess reads low)' if kept else ''}: "
        f"gyroscope_noise_density {match.gyro_noise_density:.3g}, accelerometer_noise_density "
        f"{match.accel_noise_density:.3g}, gyroscope_random_walk {match.gyro_random_walk:.3g}, "
        f"accelerometer_random_walk {match.accel_random_walk:.3g}"
    ]


# ---------------------------------------------------------------------------------------- data notes
def _span_warnings(problem: _Problem, g: _Graph) -> list[str]:
    """A note when frames with a target pose fell outside the IMU's time span and got no state."""
    outside = len(problem.frame_ids) - len(g.states)
    if outside == 0:
        return []
    frames = problem.frame_times
    return [
        f"{outside} frames with a target pose lie outside the IMU samples' time span "
        f"({problem.t_imu[0]:.3f}..{problem.t_imu[-1]:.3f} s after the recording start; frames span "
        f"{frames[0]:.3f}..{frames[-1]:.3f} s) and were dropped"
    ]


def _gap_warnings(state_times: np.ndarray) -> list[str]:
    """Notes on stretches without usable target views; the IMU factor across each one bridges it."""
    if len(state_times) < 2:
        return []
    dt = np.diff(state_times)
    limit = max(MIN_GAP_WARNING, GAP_WARNING_FACTOR * float(np.median(dt)))
    return [
        f"no usable target view for {dt[n]:.2f} s ({state_times[n]:.2f}..{state_times[n + 1]:.2f} s after the "
        "recording start, IMU clock): one IMU factor bridges the gap, with less accuracy"
        for n in np.flatnonzero(dt > limit)
    ]


# ---------------------------------------------------------------------------------------- outputs
def _extrinsic_jacobian(T_cam_imu: np.ndarray) -> np.ndarray:
    """(6, 6) map from the tangent of ``E = T_imu_cam`` to [rotation error of R_cam_imu, t_cam_imu]."""
    J = np.zeros((6, 6))
    J[:3, :3] = -np.eye(3)
    J[3:, :3] = skew(T_cam_imu[:3, 3])
    J[3:, 3:] = -np.eye(3)
    return J


def _clusters(g: _Graph, num_factors: int) -> np.ndarray:
    """The time window of every factor of the graph; -1 for the priors.

    IMU factor n joins states n and n + 1 (window of state n); a corner factor, its frame's state's.
    """
    states = g.factor_states[:num_factors]
    return np.where(states >= 0, g.state_windows[np.maximum(states, 0)], -1)


@dataclass
class _Marginals:
    """The joint covariances of every camera's variables, the first bias and the IMU intrinsics, computed once for
    all cameras of a rig (one linearisation, one elimination, one sparse factorisation).

    ``model``: the noise model's (GTSAM's marginals: NaN where the data leave a direction free); ``scaled``: under
    the measured noise levels (None with a singular information); ``robust``: the cluster-robust one or None.
    """

    columns: dict[int, np.ndarray]  # each key's rows and columns in the matrices
    model: np.ndarray
    scaled: np.ndarray | None
    robust: np.ndarray | None

    def block(self, keys: list[int]) -> tuple[np.ndarray, np.ndarray | None]:
        """The keys' covariance (the measured noise levels' where finite, else the model's) and robust one."""
        index = np.concatenate([self.columns[k] for k in keys])
        model = self.model[np.ix_(index, index)]
        if self.scaled is not None and np.all(np.isfinite(model)):
            model = self.scaled[np.ix_(index, index)]
        return model, None if self.robust is None else self.robust[np.ix_(index, index)]


def _camera_keys(index: int, joint: bool, fixed_offset: bool) -> list[int]:
    return ([_key("k", index)] if joint else []) + [_key("e", index)] + ([] if fixed_offset else [_key("d", index)])


def _marginals(problem: _Problem, g: _Graph, values: gtsam.Values, joint: bool, estimated_imu: bool) -> _Marginals:
    fixed = not problem.options.estimate_time_offset
    keys = [k for index in range(len(problem.others) + 1) for k in _camera_keys(index, joint, fixed)]
    keys += [_key("b", 0)] + ([I_KEY] if estimated_imu else [])
    linear = g.graph.linearize(values)
    model = covariance_or_unobservable(linear, values, keys)
    scale = _variance_scale(problem, g, linear.size())
    found = sandwich_covariances(linear, values, keys, _clusters(g, linear.size()), scale)
    zero = values.zeroVectors()
    sizes = [zero.at(k).size for k in keys]
    starts = np.cumsum([0, *sizes])
    columns = {k: np.arange(starts[n], starts[n + 1]) for n, k in enumerate(keys)}
    return _Marginals(columns, model, None if found is None else found[0], None if found is None else found[1])


def _parameter_covariance(
    marginals: _Marginals,
    values: gtsam.Values,
    T_cam_imu: np.ndarray,
    joint: bool,
    fixed_offset: bool,
    index: int = 0,
    imu_theta: np.ndarray | None = None,
):
    """(P, P) covariance in the order of the result's parameter names and its widening (P,) over the noise model's.

    Of camera ``index``'s variables (0: the first camera's), the first bias and, with ``imu_theta`` (the
    estimated IMU intrinsics), those. The covariance under the measured noise levels widened wherever the
    cluster-robust one (``vical.calib.robust_covariance``) is larger; a fixed time offset gets zero variance.
    """
    intrinsic_keys = [] if imu_theta is None else [I_KEY]
    model, robust = marginals.block([*_camera_keys(index, joint, fixed_offset), _key("b", 0), *intrinsic_keys])
    cov = model if robust is None else widen(model, robust)
    offset_block = np.zeros((1, 0)) if fixed_offset else np.eye(1)
    camera_block = [np.eye(values.atVector(_key("k", index)).size)] if joint else []
    blocks = camera_block + [_extrinsic_jacobian(T_cam_imu), offset_block, np.eye(6)]
    blocks += [] if imu_theta is None else [np.eye(len(imu_theta))]
    J = np.zeros((sum(b.shape[0] for b in blocks), cov.shape[0]))
    r = c = 0
    for b in blocks:
        J[r : r + b.shape[0], c : c + b.shape[1]] = b
        r, c = r + b.shape[0], c + b.shape[1]
    final, noise_model = J @ cov @ J.T, J @ model @ J.T
    with np.errstate(divide="ignore", invalid="ignore"):
        widening = np.sqrt(np.diag(final) / np.diag(noise_model))
    return final, np.where(np.isfinite(widening), widening, 1.0)


def _widening_warning(names: list[str], widening: np.ndarray) -> list[str]:
    wide = [(n, w) for n, w in zip(names, widening, strict=True) if w > WIDENING_WARNING]
    if not wide:
        return []
    listing = ", ".join(f"{n} {w:.1f}x" for n, w in sorted(wide, key=lambda x: -x[1]))
    return [
        "the parameters move more with the data over time than the noise model explains (unmodelled effects such "
        f"as a rolling shutter or detector biases): their 1-sigma were widened to match ({listing})"
    ]


def _reprojection(problem: _Problem, g: _Graph, values: gtsam.Values) -> tuple[np.ndarray, np.ndarray]:
    """Corner residuals (N, 2) [px] and the recording frame index (N,) of each corner."""
    frames = np.array([problem.observations[problem.frame_ids[k]].index for k in g.states])
    return g.corners.residuals(values), frames[g.corners.frame_of]


def _frame_log(
    frames: CameraFrames, every: list[FrameObservation], problem: _Problem, g: _Graph, used: np.ndarray
) -> FrameLog:
    """Every input frame: its corners found and used, and why a frame was left out (``vical.calib.frame_log``)."""
    inside = {problem.frame_ids[k] for k in g.states}
    outside = [problem.observations[k].index for k in problem.frame_ids if k not in inside]
    decided = left_out(every, problem.observations, problem.outliers) | {k: "outside_imu" for k in outside}
    return build_frame_log(frames, used, min(MIN_INIT_CORNERS, problem.target.num_points), decided)


def _time_offset_trace(
    problem: _Problem,
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


def _imu_residuals(g: _Graph, values: gtsam.Values, gravity_magnitude: float) -> ImuResiduals:
    """Mean rates per IMU factor: measured (preintegrated, bias-corrected to first order) vs from the states."""
    gravity = np.asarray(values.atUnit3(G_KEY).point3()) * gravity_magnitude
    rows = []
    for n, f, dt in g.imu_factors:
        pim = f.measurement(values) if isinstance(f, IntrinsicImuFactor) else f.preintegratedMeasurements()
        bias_hat, bias = pim.biasHat(), values.atConstantBias(_key("b", n))
        X0, X1 = values.atPose3(_key("x", n)), values.atPose3(_key("x", n + 1))
        v0, v1 = values.atVector(_key("v", n)), values.atVector(_key("v", n + 1))
        R0 = X0.rotation().matrix()
        d_bg = np.asarray(bias.gyroscope()) - np.asarray(bias_hat.gyroscope())
        d_ba = np.asarray(bias.accelerometer()) - np.asarray(bias_hat.accelerometer())
        gyro_meas = gtsam.Rot3.Logmap(pim.deltaRij()) / dt - d_bg
        gyro_pred = gtsam.Rot3.Logmap(X0.rotation().between(X1.rotation())) / dt
        accel_meas = np.asarray(pim.deltaVij()) / dt - d_ba
        accel_pred = R0.T @ (v1 - v0 - gravity * dt) / dt
        rows.append(np.concatenate([[g.state_times[n] + 0.5 * dt], gyro_meas, gyro_pred, accel_meas, accel_pred]))
    a = np.array(rows).reshape(-1, 13)
    return ImuResiduals(a[:, 0], a[:, 1:4], a[:, 4:7], a[:, 7:10], a[:, 10:13])


def _result(
    task: str, problem: _Problem, g: _Graph, solution, est: _Estimate, iterations: int, start: float, marginals
):
    joint = task == "joint"
    values = solution.values
    camera = problem.camera
    covariance, widening = _parameter_covariance(
        marginals, values, est.T_cam_imu, joint, not problem.options.estimate_time_offset, imu_theta=est.imu_theta
    )
    names = (intrinsic_names(camera.distortion) if joint else []) + EXTRINSIC_NAMES + BIAS_NAMES
    if est.imu_theta is not None:
        names += ImuIntrinsics.parameter_names(problem.options.g_sensitivity)
    found = correlations(names, covariance)
    problem.warnings += _widening_warning(names, widening) + correlation_warnings(found)
    problem.warnings += unobservable_warnings(names, covariance)
    estimate = np.concatenate(
        ([camera.intrinsics, camera.dist] if joint else [])
        + [np.zeros(3), est.T_cam_imu[:3, 3], [est.tau0], est.accel_bias, est.gyro_bias]
        + ([] if est.imu_theta is None else [est.imu_theta])
    )
    residuals, frame_index = _reprojection(problem, g, values)
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
        weak_parameters=weak_parameters(names, covariance, camera),
        correlations=found,
        reprojection=ResidualStats.of(residuals),
        reprojection_residuals=residuals,
        reprojection_frames=frame_index,
        imu_residuals=_imu_residuals(g, values, problem.options.gravity_magnitude),
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
    )


def _imu_intrinsics(options: ViOptions, est: _Estimate) -> ImuIntrinsics | None:
    """The estimated intrinsics, the given ones when they were kept fixed, or None."""
    return options.imu_intrinsics if est.imu_theta is None else ImuIntrinsics.from_vector(est.imu_theta)


def _other_result(
    task: str,
    problem: _Problem,
    g: _Graph,
    solution,
    est: _Estimate,
    entry,
    given: CameraInput,
    first: CalibrationResult,
    marginals: _Marginals,
):
    """Another camera's result: its parameters with the shared biases, its residuals, corners, frames and time-offset
    evidence, the shared IMU residuals."""
    other, factors, paired, frame_index = entry
    joint = task == "joint"
    values = solution.values
    covariance, widening = _parameter_covariance(
        marginals, values, other.T_cam_imu, joint, not problem.options.estimate_time_offset, other.index
    )
    camera = other.camera
    names = (intrinsic_names(camera.distortion) if joint else []) + EXTRINSIC_NAMES + BIAS_NAMES
    found = correlations(names, covariance)
    notes = other.warnings + _widening_warning(names, widening) + correlation_warnings(found)
    dropped = len(other.observations) - len(paired)
    if dropped:
        notes.append(f"{other.name}: {dropped} views without a simultaneous view of the first camera were not used")
    estimate = np.concatenate(
        ([camera.intrinsics, camera.dist] if joint else [])
        + [np.zeros(3), other.T_cam_imu[:3, 3], [other.tau0], est.accel_bias, est.gyro_bias]
    )
    residuals = factors.residuals(values)
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
        weak_parameters=weak_parameters(names, covariance, camera),
        correlations=found,
        reprojection=ResidualStats.of(residuals),
        reprojection_residuals=residuals,
        reprojection_frames=used_frames,
        reprojection_pixels=factors.measured,
        pixel_sigma=other.sigma_px,
        num_frames=len(paired),
        warnings=notes + unobservable_warnings(names, covariance),
        frame_log=_other_frame_log(problem, other, given, used_frames),
        time_offset_trace=trace,
        frame_poses=FramePoses(
            np.array([o.t_ns for o in other.observations], dtype=np.int64), np.linalg.inv(other.T_target_cam)
        ),
    )


def _other_frame_log(problem: _Problem, other: OtherCamera, given: CameraInput, used_frames: np.ndarray):
    """Another camera's ``FrameLog`` over its own frames (None without them): its views with a target pose that no
    first-camera state took are ``unpaired``."""
    if given.frames is None:
        return None
    paired = set(used_frames.tolist())
    unpaired = {o.index: "unpaired" for o in other.observations if o.index not in paired}
    strided = given.observations[:: problem.options.frame_stride]
    decided = left_out(given.observations, strided, other.outliers) | unpaired
    return build_frame_log(given.frames, used_frames, min(MIN_INIT_CORNERS, problem.target.num_points), decided)


@dataclass(frozen=True)
class CameraInput:
    """One camera of a rig for the camera-IMU solve.

    Attributes:
        name: its Kalibr name (``cam1``, ...).
        observations: its frames' detections; camera: its model (the intrinsic stage's, or known).
        initial_T_cam_imu: (4, 4) guess whose translation is used, or None (from the first camera's).
        initial_time_offset: [s] centre of its time-offset scan.
        frames: its input frames (``observations`` were collected from them), for its frame log; None: no log
            (the first camera always has them).
    """

    name: str
    observations: list[FrameObservation]
    camera: CameraModel
    initial_T_cam_imu: np.ndarray | None = None
    initial_time_offset: float = 0.0
    frames: CameraFrames | None = None


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
    (``vical.calib.pipeline.calibrate_rig`` calls it).

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
    problem = _prepare(observations, imu, camera, target, imu_noise, options, float(initial_time_offset))
    problem.warnings += noise_warnings
    est = _initial_estimate(problem, T_guess, float(initial_time_offset))
    problem.others = [_initial_other(problem, est, index, other) for index, other in enumerate(others, start=1)]
    joint = task == "joint"
    g, solution, est, iterations = _solve_rounds(problem, est, joint)
    g, solution, est, more, measured = _reweighted_solve(problem, g, solution, est, joint)
    problem.noise_factors = _measured_noise(problem, g, solution.values, measured)
    problem.imu_noise_scale *= problem.noise_factors[1]  # the weight's scale times what remains at the solution
    problem.warnings += _span_warnings(problem, g) + _gap_warnings(g.state_times)
    problem.warnings += _imu_noise_warning(problem.imu_noise_scale, imu_noise, options.noise_weighting)
    marginals = _marginals(problem, g, solution.values, joint, est.imu_theta is not None)
    result = _result(task, problem, g, solution, est, iterations + more, start, marginals)
    result = replace(result, frame_log=_frame_log(frames, every, problem, g, result.reprojection_frames))
    return [result] + [
        _other_result(task, problem, g, solution, est, entry, given, result, marginals)
        for entry, given in zip(g.others, others, strict=True)
    ]


def _initial_other(problem: _Problem, est: _Estimate, index: int, given: CameraInput) -> OtherCamera:
    """Another camera's views, PnP poses and closed-form guesses (``vical.calib.rig``)."""
    opts = problem.options
    other = prepare_other(
        given.name, index, given.observations[:: opts.frame_stride], given.camera, problem.target,
        problem.t0_ns, opts.pixel_sigma, given.initial_T_cam_imu,
    )  # fmt: skip
    initialise_other(
        other, problem.frame_times, problem.T_target_cam, est.T_cam_imu, (problem.t_imu, problem.gyro),
        opts.max_time_offset, float(given.initial_time_offset), opts.estimate_time_offset,
    )  # fmt: skip
    return other

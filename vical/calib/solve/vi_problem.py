"""The camera-IMU graph's settings (``ViOptions``), constants, and its problem: the views, PnP poses, outlier
screen and closed-form initial estimate it is built from (``vical.calib.solve.visual_inertial``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import gtsam
import numpy as np

from vical.calib.errors import CalibrationError, CalibrationSettingError
from vical.calib.result import FramePoses
from vical.calib.solve.corner_noise import corner_noise
from vical.calib.solve.imu_intrinsics import check_excitation
from vical.calib.solve.imu_intrinsics import check_model as check_imu_model
from vical.calib.solve.initialization import MIN_INIT_CORNERS, starting_poses
from vical.calib.solve.observations import FrameObservation
from vical.calib.solve.outliers import reject_outliers
from vical.calib.solve.rig import OtherCamera
from vical.calib.solve.time_alignment import align, rotation_increments
from vical.data import CameraFrames, ImuNoise, ImuSamples, Target, seconds_since
from vical.data.imu_grade import REAL_DATA_GRADE, ImuGrade, imu_grade
from vical.data.imu_model import ImuIntrinsics
from vical.geometry import CameraModel, invert_transform, make_transform

GRAVITY_MAGNITUDE = 9.81  # [m/s^2]
GYRO_BIAS_PRIOR_SIGMA = 0.1  # [rad/s] weak prior on the first gyro bias (keeps short recordings well posed)
ACCEL_BIAS_PRIOR_SIGMA = 1.0  # [m/s^2] weak prior on the first accelerometer bias
RECENTRE_OFFSET = 1e-3  # [s] re-linearise the states at the new offset when the in-graph correction exceeds this
MAX_ROUNDS = 3
# Noise levels (vical.calib.solve.variance): a sensor whose residuals say its noise is off by more than this
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
# The readout's prior (a rolling shutter's line delay times the image height): centred on the given line delay
# (0 unless a camchain gives one), as wide as a readout can be (5-30 ms for 480-1080 rows), so that observed
# readouts are the data's alone. A readout whose 1-sigma stays above READOUT_UNOBSERVED of the prior's is
# left at its prior (vical.calib.solve.rolling_shutter).
READOUT_PRIOR_SIGMA = 0.03  # [s]

E_KEY, G_KEY, D_KEY, K_KEY, I_KEY, L_KEY = (gtsam.symbol(c, 0) for c in "egdkil")
EXTRINSIC_NAMES = ["rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "time_offset"]
LINE_DELAY_NAME = "line_delay"  # [s/row], after time_offset when the graph estimates it
BIAS_NAMES = ["ba_x", "ba_y", "ba_z", "bg_x", "bg_y", "bg_z"]  # GTSAM's ConstantBias order: accel, then gyro


def state_key(c: str, i: int) -> int:
    return gtsam.symbol(c, i)


def row_centre(options: ViOptions) -> float:
    """The image row (a fraction of its height) whose exposure the states' times are: the middle while the time
    offset is estimated (its correction then hardly moves with the readout's), row 0 (the timestamp's) when it is
    held (``vical.calib.solve.corner_factors``)."""
    return 0.5 if options.estimate_time_offset else 0.0


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
            with the stride that fits (``vical.calib.solve.checks``).
        imu_model: ``calibrated`` (the readings, corrected by ``imu_intrinsics`` when given, are
            exact up to noise and bias) or ``scale-misalignment`` (estimate the IMU intrinsics,
            starting from ``imu_intrinsics``; Kalibr's model of that name).
        g_sensitivity: with ``scale-misalignment``, also estimate the gyro's g-sensitivity.
        imu_intrinsics: the IMU's known intrinsics (e.g. from Kalibr's imu.yaml), or None (identity).
        noise_weighting: how the sensors' measured noise enters the solve (``NOISE_WEIGHTINGS``).
        imu_grade: the IMU's declared scale and misalignment 1-sigma (``vical.data.imu_grade``), counted as a
            consider-prior where the data do not determine them (``vical.calib.solve.imu_model_error``); None: none
            declared, as ``calibrated`` (``with_default_grade`` resolves a recording's default).
        rolling_shutter: estimate each camera's line delay (a rolling shutter) with the time offset, every
            corner seen at its row's time; without it a camera's given line delay (``CameraInput.line_delay``,
            0: a global shutter) is used as it is.
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
    imu_grade: ImuGrade | None = None
    rolling_shutter: bool = False

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
        if self.estimate_imu_intrinsics and self.imu_grade is not None and self.imu_grade.perfect:
            raise CalibrationSettingError(
                "the IMU grade 'calibrated' says the IMU has no scale or misalignment, but {imu_model} estimates "
                "them: declare the IMU's grade ({fix}, or consumer) or calibrate with the calibrated IMU model",
                "imu_grade",
                "GRADES['industrial']",
                "industrial",
                {"imu_model": ("'scale-misalignment'", "scale-misalignment")},
            )

    @property
    def estimate_imu_intrinsics(self) -> bool:
        return self.imu_model == "scale-misalignment"

    def with_default_grade(self, sensor_grade: ImuGrade | None) -> ViOptions:
        """These options with the grade the solve counts: their own where declared; else ``calibrated`` where
        ``imu_intrinsics`` correct the readings; else ``sensor_grade`` (a simulated sensor's own, None: unknown);
        else a real IMU's default (``REAL_DATA_GRADE``). Unchanged where the scale-misalignment model estimates
        the terms instead."""
        if self.imu_grade is not None or self.estimate_imu_intrinsics:
            return self
        if self.imu_intrinsics is not None:
            grade = imu_grade("calibrated")
        else:
            grade = sensor_grade if sensor_grade is not None else imu_grade(REAL_DATA_GRADE)
        return replace(self, imu_grade=grade)

    def initial_imu_theta(self) -> np.ndarray:
        """The intrinsics' starting parameters (``ImuIntrinsics.vector``)."""
        return (self.imu_intrinsics or ImuIntrinsics()).vector(self.g_sensitivity)


@dataclass
class ViProblem:
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
    noise: ImuNoise  # the densities the IMU is weighted with (the declared ones, scaled as the solve reweights)
    declared_noise: ImuNoise  # the densities as given: the report's bounds
    options: ViOptions
    t0_ns: int
    sigma_px: float = 1.0
    imu_noise_scale: float = 1.0  # a posteriori / declared IMU noise (the variance factors' product)
    # (cameras, IMU) noise the residuals show at the final solution over the noise they were weighted with
    noise_factors: tuple[float, float] = (1.0, 1.0)
    warnings: list[str] = field(default_factory=list)
    others: list[OtherCamera] = field(default_factory=list)  # a rig's other cameras
    outliers: list[int] = field(default_factory=list)  # frame indices of the frames dropped as outliers
    readout_given: float = 0.0  # [s] the first camera's given line delay times its height (the readout's prior)


@dataclass
class ViEstimate:
    """The current extrinsic estimate (input to a round, output of it)."""

    T_cam_imu: np.ndarray
    tau0: float
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    imu_theta: np.ndarray | None = None  # IMU intrinsics (ImuIntrinsics.vector) when estimated
    readout: float = 0.0  # [s] the first camera's readout time (line delay times image height)


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


def prepare_problem(
    frames_obs: list[FrameObservation],
    imu: ImuSamples,
    camera: CameraModel,
    target: Target,
    noise: ImuNoise,
    options: ViOptions,
    offset_guess: float,
    start_poses: FramePoses | None = None,
) -> ViProblem:
    frame_t_ns = np.array([o.t_ns for o in frames_obs], dtype=np.int64)
    t0_ns = int(min(imu.t[0], frame_t_ns.min())) if len(imu) else int(frame_t_ns.min())
    _check_overlap(imu, frame_t_ns, t0_ns, offset_guess)
    min_corners = min(MIN_INIT_CORNERS, target.num_points)
    initial = starting_poses(camera, frames_obs, min_corners, start_poses)
    rejection = reject_outliers(camera, frames_obs, initial, min_corners)
    frames_obs, poses = rejection.observations, rejection.poses
    if len(poses) < 3:
        raise CalibrationError(
            f"only {len(poses)} frames have a usable target pose; camera-IMU calibration needs a sequence of views"
        )
    ids = sorted(poses)
    sigma = options.pixel_sigma
    if sigma is None:
        sigma = corner_noise(camera, [(frames_obs[k], poses[k]) for k in ids], options.rolling_shutter)
    gyro, accel = imu.gyro, imu.accel
    if options.estimate_imu_intrinsics:
        check_excitation(gyro, accel)
    elif options.imu_intrinsics is not None:
        gyro, accel = options.imu_intrinsics.correct(gyro, accel)
    return ViProblem(
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
        declared_noise=noise,
        options=options,
        t0_ns=t0_ns,
        sigma_px=float(sigma),
        warnings=list(rejection.warnings),
        outliers=list(rejection.dropped),
    )


def initial_estimate(problem: ViProblem, T_guess: np.ndarray, tau_guess: float) -> ViEstimate:
    """Closed-form time offset, rotation and gyro bias; translation from the guess."""
    inc = rotation_increments(problem.frame_times, problem.T_target_cam[:, :3, :3])
    opts = problem.options
    alignment = align(problem.t_imu, problem.gyro, inc, opts.max_time_offset, tau_guess, opts.estimate_time_offset)
    theta = opts.initial_imu_theta() if opts.estimate_imu_intrinsics else None
    return ViEstimate(
        make_transform(alignment.R_cam_imu, T_guess[:3, 3]),
        alignment.time_offset - row_centre(opts) * problem.readout_given,  # the PnP poses time the middle rows
        alignment.gyro_bias, np.zeros(3), theta, problem.readout_given,
    )  # fmt: skip


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
        start_poses: its frames' poses from the joint task's intrinsic start (PnP poses the others).
        line_delay: [s/row] its known line delay (0: a global shutter), the centre of its prior when estimated.
    """

    name: str
    observations: list[FrameObservation]
    camera: CameraModel
    initial_T_cam_imu: np.ndarray | None = None
    initial_time_offset: float = 0.0
    frames: CameraFrames | None = None
    start_poses: FramePoses | None = None
    line_delay: float = 0.0

"""What a calibration returns: estimates, their 1-sigma, quality statistics and solver facts."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vical.calib.frame_log import FrameLog
from vical.data.imu import ImuNoise
from vical.data.imu_model import ImuIntrinsics
from vical.geometry import CameraModel


@dataclass(frozen=True)
class ResidualStats:
    """Summary of residual magnitudes (px for reprojection, rad/s for gyro, m/s^2 for accel).

    Attributes:
        mean, median, std, rms, max: of the residual norms.
        count: number of residuals.
    """

    mean: float
    median: float
    std: float
    rms: float
    max: float
    count: int

    @classmethod
    def of(cls, residuals: np.ndarray) -> ResidualStats:
        """Statistics of the norms of ``residuals`` (N, D)."""
        r = np.asarray(residuals, dtype=float)
        norms = np.linalg.norm(r.reshape(len(r), -1), axis=1) if len(r) else np.zeros(0)
        if not len(norms):
            return cls(np.nan, np.nan, np.nan, np.nan, np.nan, 0)
        return cls(
            float(norms.mean()),
            float(np.median(norms)),
            float(norms.std()),
            float(np.sqrt(np.mean(norms**2))),
            float(norms.max()),
            len(norms),
        )


@dataclass(frozen=True)
class WeakParameter:
    """A parameter whose 1-sigma exceeds what a good data set reaches.

    Attributes:
        name: parameter name (see ``CalibrationResult.parameter_names``).
        sigma: its 1-sigma in the parameter's unit.
        threshold: the 1-sigma [same unit] above which it counts as weakly observed.
        hint: what motion would help, in plain words.
    """

    name: str
    sigma: float
    threshold: float
    hint: str

    @property
    def ratio(self) -> float:
        return self.sigma / self.threshold


@dataclass(frozen=True)
class Correlation:
    """Two parameters of different groups whose estimates are correlated.

    Attributes:
        a, b: parameter names; rho: their correlation coefficient in [-1, 1];
        hint: what motion would separate them, in plain words.
    """

    a: str
    b: str
    rho: float
    hint: str


@dataclass(frozen=True)
class ImuResiduals:
    """Gyro and accelerometer residuals per IMU factor (state interval), for reports and plots.

    Attributes:
        t: (S,) [s] interval mid times, relative to the recording start.
        gyro_measured, gyro_predicted: (S, 3) [rad/s] mean angular rate over the interval from the
            gyro (bias-corrected) and from the estimated states.
        accel_measured, accel_predicted: (S, 3) [m/s^2] mean specific-force change expressed as the
            velocity change per second from the accelerometer and from the estimated states.
        dt: (S,) [s] each interval's length: white noise of density ``d`` gives its means a sigma ``d / sqrt(dt)``.
        gyro_bias, accel_bias: (S, 3) [rad/s], [m/s^2] the estimated biases at each interval's first state.
        noise: the IMU's noise as declared (not as the solve reweighted it): the report's bounds.
    """

    t: np.ndarray
    gyro_measured: np.ndarray
    gyro_predicted: np.ndarray
    accel_measured: np.ndarray
    accel_predicted: np.ndarray
    dt: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    noise: ImuNoise

    @property
    def gyro_sigma(self) -> np.ndarray:
        """(S,) [rad/s] each interval's mean-rate sigma per axis from the declared white noise."""
        return self.noise.gyro_noise_density / np.sqrt(self.dt)

    @property
    def accel_sigma(self) -> np.ndarray:
        """(S,) [m/s^2] each interval's mean specific-force sigma per axis from the declared white noise."""
        return self.noise.accel_noise_density / np.sqrt(self.dt)

    @property
    def gyro_stats(self) -> ResidualStats:
        return ResidualStats.of(self.gyro_measured - self.gyro_predicted)

    @property
    def accel_stats(self) -> ResidualStats:
        return ResidualStats.of(self.accel_measured - self.accel_predicted)


@dataclass(frozen=True)
class FramePoses:
    """A camera's frames with a PnP pose: what the camera-IMU solve started from, and what the evidence checks of
    ``vical.calib.solve.plausibility`` read (so PnP runs once per frame).

    Attributes:
        t_ns: (F,) int64 [ns] their stamps (camera clock); T_cam_target: (F, 4, 4) their poses.
    """

    t_ns: np.ndarray
    T_cam_target: np.ndarray


@dataclass(frozen=True)
class TimeOffsetTrace:
    """The camera's rotation rate against the gyro's, the evidence for the time offset (times [s] since one start).

    Attributes:
        t_camera: (M,) [s] middle of each pair of consecutive frames with a target pose (camera clock).
        omega_camera: (M, 3) [rad/s] the camera's mean rotation rate over each pair (PnP poses), in the IMU frame.
        t_imu: (N,) [s] IMU sample times; gyro: (N, 3) [rad/s] the gyro minus the estimated bias.
        shifts: (G,) [s] time offsets around the estimate; mismatch: (G,) [rad] RMS difference between the
            camera's rotation increments and the gyro's integrated over the same pairs shifted by each offset.
    """

    t_camera: np.ndarray
    omega_camera: np.ndarray
    t_imu: np.ndarray
    gyro: np.ndarray
    shifts: np.ndarray
    mismatch: np.ndarray


@dataclass(frozen=True)
class UnmodelledImuTerms:
    """What one IMU sensor's scales and misalignments, which the ``calibrated`` model does not estimate, add to a
    result's covariance: ``effect @ spread @ effect.T`` (``vical.calib.solve.imu_model_error``).

    Two results of one IMU (windows of one recording) share the terms: their difference's covariance holds
    ``(effect_a - effect_b) spread (effect_a - effect_b)^T`` of them, not the sum of both.

    Attributes:
        sensor: ``gyro`` or ``accelerometer``.
        effect: (P, 6) the parameters' first-order shift per unit of its entries (scales - 1, misalignments [rad]).
        spread: (6, 6) the expected square of the entries the solve leaves uncorrected.
    """

    sensor: str
    effect: np.ndarray
    spread: np.ndarray

    def covariance(self) -> np.ndarray:
        return self.effect @ self.spread @ self.effect.T


@dataclass(frozen=True)
class CalibrationResult:
    """The outcome of ``calibrate_intrinsics`` / ``calibrate_extrinsics`` / ``calibrate_joint``.

    Attributes:
        task: ``"intrinsic"``, ``"extrinsic"``, ``"joint"`` or ``"two_stage"``.
        camera: the camera model (estimated, or the given one for the extrinsic task).
        T_cam_imu: (4, 4) camera-IMU extrinsic (maps IMU points into the camera frame) or None.
        time_offset: [s] Kalibr's ``timeshift_cam_imu`` (``t_imu = t_cam + time_offset``) or None.
        gyro_bias: (3,) [rad/s] and accel_bias (3,) [m/s^2] at the first IMU state, or None.
        gravity_target: (3,) [m/s^2] gravity in the target frame, or None.
        parameter_names: names of the entries of ``estimate`` / ``covariance``: ``fx fy cx cy``
            [px], ``d0..d3`` (distortion), ``rot_x rot_y rot_z`` [rad] (rotation error of
            ``R_cam_imu`` as a rotation vector in the camera frame, left perturbation),
            ``t_x t_y t_z`` [m] (translation of ``T_cam_imu``), ``time_offset`` [s],
            ``line_delay`` [s/row] (when estimated), ``bg_x..bg_z`` [rad/s], ``ba_x..ba_z`` [m/s^2].
        estimate: (P,) values of those parameters (0 for the rotation perturbation).
        covariance: (P, P) their marginal covariance from the factor graph.
        weak_parameters: weakly observed parameters, the weakest first, with motion hints.
        reprojection: reprojection error statistics [px].
        reprojection_residuals: (N, 2) [px] measured minus predicted corner positions.
        reprojection_frames: (N,) int index of the frame (in the input ``CameraFrames``) of each residual.
        imu_residuals: gyro / accel residuals per IMU factor or None (intrinsic task).
        pixel_sigma: [px] the corner noise used to weight the projection factors.
        iterations: Levenberg-Marquardt iterations.
        solve_time: [s] wall time of the whole calibration (initialisation, solve, covariance).
        status: ``"converged"`` or ``"max_iterations"``.
        num_frames: frames that entered the graph.
        warnings: plain-language notes about the data (dropped frames, estimated noise).
        imu_noise_scale: the IMU's noise measured from its residuals over the declared densities
            (``vical.calib.solve.variance``; the solve weighted the IMU by it), or None (intrinsic task).
        correlations: the strongest correlations between parameter groups, strongest first.
        frame_log: every input frame's detected and used corners, and why a frame was not used (the
            final solve's frames: the extrinsic stage's in the two-stage task).
        reprojection_pixels: (N, 2) [px] the measured corner of each residual, or None.
        time_offset_trace: the camera's rotation rate against the gyro's, or None (intrinsic task).
        imu_intrinsics: the IMU's scale, misalignment and g-sensitivity (estimated with
            ``imu_model="scale-misalignment"``, else the known ones given), or None.
        frame_poses: the PnP poses the camera-IMU solve started from, or None (intrinsic task).
        line_delay: [s/row] the camera's rolling shutter (row ``v`` exposed ``line_delay * v`` after the
            timestamp): estimated, or the known one the solve used; None for a global shutter.
        rolling_shutter_evidence: [s] the readout a global-shutter solve's residuals show where they show one
            (``vical.calib.solve.rolling_shutter``: a lower bound), else None.
        unmodelled_imu: what the IMU's unmodelled scales and misalignments add to ``covariance``, per sensor
            (``UnmodelledImuTerms``; empty: nothing, e.g. the intrinsic task or the scale-misalignment model).
    """

    task: str
    camera: CameraModel
    T_cam_imu: np.ndarray | None
    time_offset: float | None
    gyro_bias: np.ndarray | None
    accel_bias: np.ndarray | None
    gravity_target: np.ndarray | None
    parameter_names: list[str]
    estimate: np.ndarray
    covariance: np.ndarray
    weak_parameters: list[WeakParameter]
    reprojection: ResidualStats
    reprojection_residuals: np.ndarray
    reprojection_frames: np.ndarray
    imu_residuals: ImuResiduals | None
    pixel_sigma: float
    iterations: int
    solve_time: float
    status: str
    num_frames: int
    warnings: list[str] = field(default_factory=list)
    imu_noise_scale: float | None = None
    correlations: list[Correlation] = field(default_factory=list)
    frame_log: FrameLog | None = None
    reprojection_pixels: np.ndarray | None = None
    time_offset_trace: TimeOffsetTrace | None = None
    imu_intrinsics: ImuIntrinsics | None = None
    frame_poses: FramePoses | None = None
    # Reprojection rms [px] of every lens model calibrated on these corners, where the one used did not fit
    # (vical.calib.solve.model_fit); None where it fit, or nothing was compared.
    model_fits: dict[str, float] | None = None
    # (residual field, corner noise) [px per axis]: how far the corners' residuals depend on their image position,
    # the same in every view, beside their noise (vical.calib.solve.model_fit.lens_misfit); None where not measured.
    lens_misfit: tuple[float, float] | None = None
    line_delay: float | None = None
    rolling_shutter_evidence: float | None = None
    unmodelled_imu: list[UnmodelledImuTerms] = field(default_factory=list)

    @property
    def sigmas(self) -> dict[str, float]:
        """1-sigma of every estimated parameter, by name (units as in ``parameter_names``)."""
        return dict(zip(self.parameter_names, np.sqrt(np.diag(self.covariance)).tolist(), strict=True))

    def sigma(self, name: str) -> float:
        """1-sigma of one parameter."""
        return self.sigmas[name]

    def block(self, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """Estimate (k,) and covariance (k, k) of the named parameters."""
        idx = [self.parameter_names.index(n) for n in names]
        return self.estimate[idx], self.covariance[np.ix_(idx, idx)]

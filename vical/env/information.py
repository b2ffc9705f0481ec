"""How well the data collected so far determine each parameter group: the calibration's predicted 1-sigma.

``InformationTracker`` follows a recording as it grows (camera frames with detections, IMU samples)
and keeps the information matrix of the task's calibration problem, linearised at an initial guess
of the sensor (a datasheet's, or the sensor distribution's means in the simulator): never at the
simulator's truth, so a real robot computes the same. It uses the calibrator's own factors
(``vical.calib.solve.corner_factors`` per frame, GTSAM's preintegrated ``CombinedImuFactor`` between
frames), so its prediction is the calibration's covariance at that point.

Per frame with a target pose (PnP with the guessed camera), as an information filter:

- a new state (the IMU pose ``T_target_imu``, its velocity from the previous pose, zero biases)
  joins the information matrix over the shared parameters ``[gravity direction, T_imu_cam, time
  offset, camera]`` (those the task estimates) and the previous state;
- the preintegrated IMU factor from the previous state and the frame's corner factor add their
  ``A^T A``;
- the previous state is marginalised out (a Schur complement), so the matrix never grows.

In the intrinsic task each frame's camera pose is marginalised at once. Weak priors (a guess's
usual spread) keep early, unobservable directions finite. The parameters' covariance is the
inverse of their marginal information.

A lens whose distortion is not centred on the principal point (a decentred lens; the joint
task draws one on purpose) is an error the pinhole models cannot fit: it biases the estimate
whatever the amount of data. Its first-order effect on a radial lens is exactly radtan's
tangential terms (absorbed); what remains is of higher order in the offset and grows with the
distortion coefficients, so it vanishes at a guess without distortion. With a declared spread
(``Guess.lens_spread``: the offset's and the coefficients') the misfit field of every corner
(decentred minus centred projection) is carried as *considered* columns, never estimated: the
columns' cross-information ``L_pc`` with the estimated parameters ``p`` gives the bias each
leaves, ``S = inv(L_pp) L_pc`` (the least-squares fit of the misfit), and the prediction adds
their second moment ``S S^T`` to ``inv(L_pp)``. The misfit is linear in the coefficients, so
their spread enters exactly; the offset's by Gauss-Hermite nodes (3 per axis: exact for the
misfit's terms up to second order in the offset, which carry the bias).

``sigmas()`` reduces the covariance to one 1-sigma per group in the units users read: focal
length and principal point [px], distortion [px of displacement at the image corner], extrinsic
rotation [deg] and translation [mm] (largest axis), time offset [ms].
"""

from __future__ import annotations

import copy
import functools
from dataclasses import dataclass

import gtsam
import numpy as np
from scipy.stats import chi2

from vical.calib.metrics import corner_ray
from vical.calib.solve.corner_factors import CornerFactors, CornerKeys
from vical.calib.solve.imu_integration import interpolate, interval_segments, preintegrate, preintegration_params
from vical.calib.solve.imu_model_error import ACCEL, GYRO, mean_readings, reading_jacobian
from vical.calib.solve.initialization import MIN_INIT_CORNERS, pnp
from vical.calib.solve.observations import FrameObservation
from vical.calib.solve.outliers import robust_sigma_of_norms
from vical.data import ImuNoise, ImuSamples, Target
from vical.data.imu_grade import ImuGrade
from vical.geometry import CameraModel, invert_transform

GROUPS = ("focal", "principal_point", "distortion", "rotation", "translation", "time_offset")
UNITS = {"focal": "px", "principal_point": "px", "distortion": "px", "rotation": "deg", "translation": "mm",
         "time_offset": "ms"}  # fmt: skip
TASK_GROUPS = {
    "intrinsic": GROUPS[:3],
    "extrinsic": GROUPS[3:],
    "joint": GROUPS,
}
# The groups each task's evaluation scores (vical.evaluation.seed_choice.SCORED_GROUPS): the joint task's intrinsics
# are estimated, but a decentred lens biases them beyond any tolerance.
SCORED_GROUPS = {"intrinsic": GROUPS[:3], "extrinsic": GROUPS[3:], "joint": GROUPS[3:]}
GRAVITY = 9.81  # [m/s^2]
# Prior 1-sigma of the shared parameters: the spread of a guess before any data (tangent units).
PRIOR_SIGMA = {
    "K": np.array([50.0, 50.0, 30.0, 30.0, 0.2, 0.2, 0.01, 0.01]),  # [px] x 4, distortion [-] x 4
    "K_wide_angle": np.array([50.0, 50.0, 30.0, 30.0, 0.2, 0.1]),  # [px] x 4, ds [xi, alpha] / eucm [alpha, beta] [-]
    "E": np.r_[np.full(3, 0.2), np.full(3, 0.05)],  # [rad], [m]
    "D": np.array([0.05]),  # [s]
    "G": np.full(2, 0.5),  # [rad] gravity direction
}
BIAS_PRIOR_SIGMA = np.r_[np.full(3, 1.0), np.full(3, 0.1)]  # [m/s^2], [rad/s] first state's biases, as the calibrator
MIN_PIXEL_SIGMA = 0.05  # [px] floor of the corner noise measured from the PnP residuals
RECENT_FRAMES = 200  # frames whose PnP residuals measure the corner noise
IMU_DIM = 15  # pose 6, velocity 3, bias 6 per state
# Gauss-Hermite nodes and weights of a standard normal, 3 per axis of the distortion centre's offset
# (the centre node leaves no misfit and is left out).
_NODES_1D, _WEIGHTS_1D = np.array([-np.sqrt(3.0), 0.0, np.sqrt(3.0)]), np.array([1 / 6, 2 / 3, 1 / 6])
OFFSET_NODES = np.array([(a, b) for a in _NODES_1D for b in _NODES_1D if a or b])
OFFSET_WEIGHTS = np.array([wa * wb for a, wa in zip(_NODES_1D, _WEIGHTS_1D, strict=True)
                           for b, wb in zip(_NODES_1D, _WEIGHTS_1D, strict=True) if a or b])  # fmt: skip

E_KEY, D_KEY, K_KEY, G_KEY = (gtsam.symbol(c, 0) for c in "edkg")
X_KEY, V_KEY, B_KEY = (gtsam.symbol(c, 0) for c in "xvb")  # the current state (one at a time)
X1_KEY, V1_KEY, B1_KEY = (gtsam.symbol(c, 1) for c in "xvb")  # the next one
CONSIDERED = ("C", "M")  # shared columns never estimated: a decentred lens's misfit, the IMU grade's terms


@dataclass(frozen=True)
class Guess:
    """The initial guess the information is linearised at (not the truth).

    Attributes:
        camera: camera model and parameters; T_cam_imu: (4, 4); time_offset: [s];
        imu_noise: the IMU's declared noise densities; pixel_sigma: [px] corner noise, None to
            measure it from the PnP residuals; lens_spread: how far the real lens may be from the
            camera model's (``LensSpread``), considered in the prediction; None: the model is exact.
        imu_grade: the IMU's declared scale and misalignment 1-sigma (``vical.data.imu_grade``), considered in the
            prediction as the calibrator counts it; None or ``calibrated``: exact readings.
    """

    camera: CameraModel
    T_cam_imu: np.ndarray
    time_offset: float
    imu_noise: ImuNoise
    pixel_sigma: float | None = None
    lens_spread: LensSpread | None = None
    imu_grade: ImuGrade | None = None


@dataclass(frozen=True)
class LensSpread:
    """The declared spread of a decentred lens around the guess (1-sigma of independent Gaussians).

    Attributes:
        center_offset_px: (2,) [px] the distortion centre's offset from the principal point (x, y).
        coefficient_std: (D,) the distortion coefficients' spread around the guess's (the misfit of a
            decentred lens grows with its distortion, which a guess only knows to this spread).
    """

    center_offset_px: np.ndarray
    coefficient_std: np.ndarray

    def checked(self, camera: CameraModel) -> LensSpread:
        """This spread as arrays, ``ValueError`` naming what is wrong for ``camera``'s model."""
        offset = np.asarray(self.center_offset_px, dtype=float)
        coefficient_std = np.asarray(self.coefficient_std, dtype=float)
        if offset.shape != (2,) or not np.all(np.isfinite(offset)) or np.any(offset < 0):
            raise ValueError(f"LensSpread.center_offset_px must be two numbers >= 0 [px], got {offset.tolist()}")
        if coefficient_std.shape != camera.dist.shape or np.any(~np.isfinite(coefficient_std) | (coefficient_std < 0)):
            raise ValueError(
                f"LensSpread.coefficient_std must be {len(camera.dist)} numbers >= 0 (one per {camera.distortion} "
                f"coefficient), got {coefficient_std.tolist()}"
            )
        return LensSpread(offset, coefficient_std)

    def columns(self, camera: CameraModel) -> int:
        """How many considered columns ``lens_misfits`` gives for ``camera``."""
        return len(OFFSET_NODES) * (int(_has_mean_misfit(camera)) + int(np.count_nonzero(self.coefficient_std)))


class InformationTracker:
    """The task's predicted calibration covariance as frames and IMU samples arrive.

    Args:
        task: ``intrinsic``, ``extrinsic`` or ``joint`` (which parameters are estimated).
        target: the calibration target.
        guess: where the problem is linearised (``Guess``).
    """

    def __init__(self, task: str, target: Target, guess: Guess) -> None:
        if task not in TASK_GROUPS:
            raise ValueError(f"task must be one of {sorted(TASK_GROUPS)}, got {task!r}")
        self.task, self.target, self.guess = task, target, guess
        self.uses_imu = task != "intrinsic"
        self.shared = {"intrinsic": ["K"], "extrinsic": ["G", "E", "D"], "joint": ["G", "E", "D", "K"]}[task]
        self.shared_dims = {"K": len(guess.camera.parameters), "E": 6, "D": 1, "G": 2}
        self._lens: LensSpread | None = None
        if guess.lens_spread is not None:
            _check_lens_spread(task, guess.camera)
            self._lens = guess.lens_spread.checked(guess.camera)
            self.shared_dims["C"] = self._lens.columns(guess.camera)
            self.shared.append("C")  # last: the estimated parameters keep their columns
        self._grade_sigmas = _grade_sigmas(guess.imu_grade) if self.uses_imu else None
        if self._grade_sigmas is not None:
            self.shared_dims["M"] = len(self._grade_sigmas)
            self.shared.append("M")  # considered as "C" is: the IMU's scales and misalignments
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Forget every frame: the information is the priors' (over the shared parameters only)."""
        n = self._shared_size
        self.information = np.zeros((n, n))
        offset = 0
        for name in self.estimated:
            dim = self.shared_dims[name]
            sigma = PRIOR_SIGMA["K_wide_angle" if name == "K" and self.guess.camera.is_wide_angle else name]
            self.information[offset : offset + dim, offset : offset + dim] = np.diag(1.0 / sigma**2)
            offset += dim  # the considered lens columns have no prior: they are never solved for
        self._state: tuple[float, np.ndarray] | None = None  # (IMU time [s], T_target_imu) of the last state
        self._residual_norms: list[np.ndarray] = []
        self._sigma_px = self._measured_pixel_sigma()
        self._frame_weight = 1.0  # the frames each added frame stands for (a fork's)
        self._t0: int | None = None
        self.frames_used = 0
        self.last_pose: np.ndarray | None = None  # T_target_cam (4, 4) of the last frame added (PnP, guessed camera)

    @property
    def counts_imu_grade(self) -> bool:
        """Whether the prediction considers an IMU grade's terms (a camera + IMU task, a grade other than
        ``calibrated``)."""
        return "M" in self.shared

    @property
    def estimated(self) -> list[str]:
        """The shared parameters the calibration estimates (all but the considered lens and IMU terms)."""
        return [name for name in self.shared if name not in CONSIDERED]

    @property
    def _shared_size(self) -> int:
        return sum(self.shared_dims[n] for n in self.shared)

    def add_frames(self, observations: list[FrameObservation], imu: ImuSamples) -> None:
        """Add frames (in time order, after every frame added before) and the IMU samples recorded so far."""
        posed = []
        for obs in observations:
            if len(obs.ids) < self.min_corners:
                continue
            fit = pnp(self.guess.camera, obs, refine=False)  # a linearisation point: the plane's pose suffices
            if fit is not None:
                posed.append((obs, fit[0]))
                self._residual_norms.append(np.linalg.norm(obs.residuals(self.guess.camera, fit[0]), axis=1))
        self._sigma_px = self._measured_pixel_sigma()
        self.add_posed_frames(posed, imu)

    def add_posed_frames(self, posed: list[tuple[FrameObservation, np.ndarray]], imu: ImuSamples) -> None:
        """Add frames with their target poses ``T_cam_target`` (4, 4) (``add_frames`` after PnP; a prediction's
        frames, which leave the measured corner noise as it is)."""
        for obs, T_cam_target in posed:
            T_target_cam = invert_transform(T_cam_target)
            if self.uses_imu:
                self._add_inertial_frame(obs, T_target_cam, imu)
            else:
                self._add_camera_frame(obs, T_target_cam)
            self.last_pose = T_target_cam
            self.frames_used += 1

    def fork(self, frame_weight: float = 1.0) -> InformationTracker:
        """An independent copy of the current information (what a prediction adds to it leaves this one as it is),
        in which every frame added stands for ``frame_weight`` frames (the recorded corner noise divided by its
        root; a fork of a fork weighs its own frames, not its parent's twice)."""
        other = copy.copy(self)
        other.information = self.information.copy()
        other._residual_norms = list(self._residual_norms)
        other._sigma_px = self._sigma_px * np.sqrt(self._frame_weight) / np.sqrt(frame_weight)
        other._frame_weight = frame_weight
        return other

    @property
    def min_corners(self) -> int:
        """Corners a frame needs to be posed and added (``MIN_INIT_CORNERS``, or the whole of a smaller target)."""
        return min(MIN_INIT_CORNERS, self.target.num_points)

    @property
    def last_time(self) -> float | None:
        """[s] the IMU time (since the recording's first sample) of the last frame's state; None without one."""
        return None if self._state is None else self._state[0]

    @property
    def first_stamp(self) -> int | None:
        """[ns] the stamp the IMU times count from (None before the first frame with IMU data)."""
        return self._t0

    @property
    def pixel_sigma(self) -> float:
        """[px] the corner noise the frames are weighted with (``Guess.pixel_sigma`` or measured)."""
        return self._sigma_px

    def _measured_pixel_sigma(self) -> float:
        """The guess's corner noise, or the one measured robustly from the latest frames' PnP residuals."""
        if self.guess.pixel_sigma is not None:
            return self.guess.pixel_sigma
        if not self._residual_norms:
            return 1.0
        return max(robust_sigma_of_norms(np.concatenate(self._residual_norms[-RECENT_FRAMES:])), MIN_PIXEL_SIGMA)

    # ------------------------------------------------------------------ one frame
    def _corner_factor(self, obs: FrameObservation, keys: CornerKeys):
        return CornerFactors([obs], self.guess.camera, keys, self.pixel_sigma).factors()[0]

    def _add_corners(self, block, obs, keys, values, layout, T_target_cam: np.ndarray) -> None:
        """The frame's corner factor's information, with the considered lens misfit's columns when declared."""
        linear = self._corner_factor(obs, keys).linearize(values)
        if "C" not in self.shared:
            _accumulate(block, linear, layout)
            return
        q = (obs.points - T_target_cam[:3, 3]) @ T_target_cam[:3, :3]  # the corners in the camera frame
        misfit = lens_misfits(self.guess.camera, q, self._lens) / self.pixel_sigma
        _accumulate(block, linear, layout, extra=(misfit, self._lens_columns))

    @property
    def _grade_columns(self) -> slice:
        start = sum(self.shared_dims[n] for n in self.shared if n != "M")
        return slice(start, start + self.shared_dims["M"])

    def _grade_terms(self, factor, linear, imu: ImuSamples, t_imu: np.ndarray, t_prev: float, t: float) -> np.ndarray:
        """(15, 12) the IMU factor's whitened error per 1-sigma of each of the grade's terms (the gyro's six,
        then the accelerometer's; ``vical.calib.solve.imu_model_error.reading_jacobian``): their effect, never
        estimated, considered as the lens misfit's columns are. The mean readings come from the samples around
        the interval only (``t_imu`` [s]: every sample so far, which grows with the recording)."""
        A, _ = gtsam.JacobianFactor(linear).jacobian()
        around = slice(max(int(np.searchsorted(t_imu, t_prev, "right")) - 1, 0), int(np.searchsorted(t_imu, t)) + 1)
        ends = np.array([t_prev, t])
        parts = [reading_jacobian(factor, A, mean_readings(t_imu[around], readings[around], ends)[0],
                                  sensor.bias_columns)
                 for sensor, readings in ((GYRO, imu.gyro), (ACCEL, imu.accel))]  # fmt: skip
        return np.hstack(parts) * self._grade_sigmas

    @property
    def _lens_columns(self) -> slice:
        start = sum(self.shared_dims[n] for n in self.estimated)
        return slice(start, start + self.shared_dims["C"])

    def _add_camera_frame(self, obs: FrameObservation, T_target_cam: np.ndarray) -> None:
        """Intrinsic task: the frame's pose joins, its corners add information, the pose is marginalised."""
        values = gtsam.Values()
        values.insert(X_KEY, gtsam.Pose3(T_target_cam))
        values.insert(K_KEY, self.guess.camera.parameters)
        k = self._shared_size  # K, then the considered offset when declared
        layout = {K_KEY: slice(0, self.shared_dims["K"]), X_KEY: slice(k, k + 6)}
        block = np.zeros((k + 6, k + 6))
        self._add_corners(block, obs, CornerKeys(poses=[X_KEY], camera=K_KEY), values, layout, T_target_cam)
        self.information += _schur(block, k)

    def _add_inertial_frame(self, obs: FrameObservation, T_target_cam: np.ndarray, imu: ImuSamples) -> None:
        if self._t0 is None:
            self._t0 = int(min(imu.t[0], obs.t_ns)) if len(imu) else int(obs.t_ns)
        t = (obs.t_ns - self._t0) / 1e9 + self.guess.time_offset  # the state's IMU time [s]
        t_imu = (imu.t - self._t0) / 1e9
        if len(t_imu) < 2 or not t_imu[0] <= t <= t_imu[-1]:
            return  # no IMU around this frame yet (or any more)
        T_imu = T_target_cam @ self.guess.T_cam_imu
        if self._state is None:
            self._first_state(obs, t, T_imu, imu, t_imu)
            return
        self._next_state(obs, t, T_imu, imu, t_imu)

    def _layout(self, with_next: bool) -> dict[int, slice]:
        """Columns of the shared parameters, then the current state (x, v, b), then the next one's."""
        layout, offset = {}, 0
        for name in self.estimated:
            dim = self.shared_dims[name]
            layout[{"K": K_KEY, "E": E_KEY, "D": D_KEY, "G": G_KEY}[name]] = slice(offset, offset + dim)
            offset += dim
        offset = self._shared_size  # past the considered offset's columns
        for keys in ((X_KEY, V_KEY, B_KEY), (X1_KEY, V1_KEY, B1_KEY))[: 2 if with_next else 1]:
            for key, dim in zip(keys, (6, 3, 6), strict=True):
                layout[key] = slice(offset, offset + dim)
                offset += dim
        return layout

    def _values(self, T_imu: np.ndarray, v: np.ndarray, gravity: np.ndarray, suffix: int) -> gtsam.Values:
        values = gtsam.Values()
        values.insert(E_KEY, gtsam.Pose3(invert_transform(self.guess.T_cam_imu)))
        values.insert(D_KEY, np.zeros(1))
        values.insert(K_KEY, self.guess.camera.parameters)
        values.insert(G_KEY, gtsam.Unit3(gravity))
        keys = (X_KEY, V_KEY, B_KEY) if suffix == 0 else (X1_KEY, V1_KEY, B1_KEY)
        values.insert(keys[0], gtsam.Pose3(T_imu))
        values.insert(keys[1], np.asarray(v, float))
        values.insert(keys[2], gtsam.imuBias.ConstantBias())
        return values

    def _frame_keys(self, x: int, v: int, omega: np.ndarray) -> CornerKeys:
        return CornerKeys(
            poses=[x], velocities=[v], omegas=omega[None, :], extrinsic=E_KEY, delta=D_KEY,
            camera=K_KEY if "K" in self.shared else None,
        )  # fmt: skip

    def _first_state(self, obs, t: float, T_imu: np.ndarray, imu: ImuSamples, t_imu: np.ndarray) -> None:
        specific_force = interpolate(t_imu, imu.accel, np.array([t]))[0]
        gravity = -T_imu[:3, :3] @ specific_force
        self._gravity = gravity / np.linalg.norm(gravity)
        omega = interpolate(t_imu, imu.gyro, np.array([t]))[0]
        values = self._values(T_imu, np.zeros(3), self._gravity, 0)
        layout = self._layout(with_next=False)
        n = self._shared_size + IMU_DIM
        block = np.zeros((n, n))
        block[: self._shared_size, : self._shared_size] = self.information
        T_target_cam = T_imu @ invert_transform(self.guess.T_cam_imu)
        self._add_corners(block, obs, self._frame_keys(X_KEY, V_KEY, omega), values, layout, T_target_cam)
        bias = layout[B_KEY]
        block[bias, bias] += np.diag(1.0 / BIAS_PRIOR_SIGMA**2)
        self._joint = block  # shared parameters + the current state
        self._state = (t, T_imu)

    def _next_state(self, obs, t: float, T_imu: np.ndarray, imu: ImuSamples, t_imu: np.ndarray) -> None:
        t_prev, T_prev = self._state
        if t <= t_prev:
            return
        velocity = (T_imu[:3, 3] - T_prev[:3, 3]) / (t - t_prev)
        values = self._values(T_prev, velocity, self._gravity, 0)
        for key, value in ((X1_KEY, gtsam.Pose3(T_imu)), (V1_KEY, velocity), (B1_KEY, gtsam.imuBias.ConstantBias())):
            values.insert(key, value)
        params = preintegration_params(self.guess.imu_noise)
        pim = preintegrate(
            params, gtsam.imuBias.ConstantBias(), interval_segments(t_imu, imu.gyro, imu.accel, t_prev, t)
        )
        factor = gtsam.CombinedImuFactorWithGravityDirection(
            X_KEY, V_KEY, X1_KEY, V1_KEY, B_KEY, B1_KEY, G_KEY, pim, GRAVITY
        )
        omega = interpolate(t_imu, imu.gyro, np.array([t]))[0]
        layout = self._layout(with_next=True)
        n = self._shared_size + 2 * IMU_DIM
        block = np.zeros((n, n))
        block[: self._joint.shape[0], : self._joint.shape[0]] = self._joint
        linear = factor.linearize(values)
        terms = None
        if "M" in self.shared:
            terms = (self._grade_terms(factor, linear, imu, t_imu, t_prev, t), self._grade_columns)
        _accumulate(block, linear, layout, extra=terms)
        T_target_cam = T_imu @ invert_transform(self.guess.T_cam_imu)
        self._add_corners(block, obs, self._frame_keys(X1_KEY, V1_KEY, omega), values, layout, T_target_cam)
        self._joint = _marginalise(block, layout[X_KEY].start, layout[B_KEY].stop)  # the next state is now current
        self._state = (t, T_imu)

    # ------------------------------------------------------------------ the prediction
    def _marginal(self) -> np.ndarray:
        """The shared parameters' information, the current state marginalised (symmetrised)."""
        if self.uses_imu and self._state is not None:
            marginal = _schur(self._joint, self._shared_size)
        else:
            marginal = self.information
        return 0.5 * (marginal + marginal.T)

    def covariance(self) -> tuple[list[str], np.ndarray]:
        """The estimated parameters' names and their predicted covariance (the current state marginalised;
        a declared lens spread's bias added)."""
        marginal = self._marginal()
        names = [name for name in self.estimated for _ in range(self.shared_dims[name])]
        if not set(CONSIDERED) & set(self.shared):
            return names, np.linalg.inv(marginal)
        p = len(names)
        cov = np.linalg.inv(marginal[:p, :p])
        bias = cov @ marginal[:p, p:]  # (P, columns): each column's bias, weighted so that bias @ bias.T sums them
        # (the lens misfit's and the IMU grade's alike: each column is one considered term at its 1-sigma)
        return names, cov + bias @ bias.T

    def sigmas(self) -> dict[str, float]:
        """Predicted 1-sigma of each parameter group of the task, in the units of ``UNITS``."""
        names, cov = self.covariance()
        idx = {n: [i for i, m in enumerate(names) if m == n] for n in set(names)}
        out = {}
        if "K" in idx:
            K = cov[np.ix_(idx["K"], idx["K"])]
            out["focal"] = float(np.sqrt(0.5 * (K[0, 0] + K[1, 1])))
            out["principal_point"] = float(np.sqrt(0.5 * (K[2, 2] + K[3, 3])))
            out["distortion"] = self._distortion_px(K[4:, 4:])
        if "E" in idx:
            E = cov[np.ix_(idx["E"], idx["E"])]
            out["rotation"] = float(np.degrees(np.sqrt(np.linalg.eigvalsh(E[:3, :3])[-1])))
            out["translation"] = float(1e3 * np.sqrt(np.linalg.eigvalsh(E[3:, 3:])[-1]))
            out["time_offset"] = float(1e3 * np.sqrt(cov[idx["D"][0], idx["D"][0]]))
        return out

    def axis_sigmas(self) -> np.ndarray | None:
        """(6,) predicted 1-sigma of the extrinsic along each camera axis (GTSAM's tangent of ``T_imu_cam``: the
        camera's frame): rotation about x, y, z [deg], translation along x, y, z [mm]; None where the task estimates
        no extrinsic."""
        names, cov = self.covariance()
        idx = [i for i, name in enumerate(names) if name == "E"]
        if not idx:
            return None
        sigma = np.sqrt(np.diag(cov)[idx])
        return np.r_[np.degrees(sigma[:3]), 1e3 * sigma[3:]]

    def _distortion_px(self, cov: np.ndarray) -> float:
        """1-sigma [px] of the distortion's displacement at the image corner (RMS over the two axes; a wide-angle
        lens whose image circle leaves the corner dark: at the right edge)."""
        _, _, d_params = self.guess.camera.project_jacobians(corner_ray(self.guess.camera))
        J = d_params[0][:, 4:]
        return float(np.sqrt(0.5 * np.trace(J @ cov @ J.T)))


def _grade_sigmas(grade: ImuGrade | None) -> np.ndarray | None:
    """(12,) the grade's 1-sigma of the gyro's six terms, then the accelerometer's; None for no or a perfect grade."""
    if grade is None or grade.perfect:
        return None
    return np.sqrt(np.r_[np.diag(GYRO.prior(grade)), np.diag(ACCEL.prior(grade))])


def _accumulate(block: np.ndarray, linear: gtsam.GaussianFactor, layout: dict[int, slice], extra=None) -> None:
    """Add a whitened linear factor's ``A^T A`` into ``block`` at its keys' columns; ``extra``: more columns
    of the same rows ``(A_extra, their slice)``."""
    A, _ = gtsam.JacobianFactor(linear).jacobian()
    columns = np.concatenate([np.arange(layout[k].start, layout[k].stop) for k in linear.keys()])  # noqa: SIM118
    if extra is not None:
        A = np.hstack([A, extra[0]])
        columns = np.r_[columns, np.arange(extra[1].start, extra[1].stop)]
    block[np.ix_(columns, columns)] += A.T @ A


def lens_misfits(camera: CameraModel, p_cam: np.ndarray, spread: LensSpread) -> np.ndarray:
    """(2N, columns) [px] misfit fields of a decentred lens at camera-frame points (N, 3), rows u, v per point, weighted
    so that their second moment over ``spread`` is ``columns @ columns.T``.

    A decentred lens projects ``d_k(x - s) + s`` where its model projects ``d_k(x)`` (``s`` the offset over the
    focal lengths). The pinhole models' distortion is linear in its coefficients, ``d_k = d_0 + sum_i k_i b_i``,
    so with ``k`` the guess's plus ``std_i z_i`` the misfit is ``h(s) + sum_i std_i z_i g_i(s)``; per offset node
    the columns are ``h`` (absent where it vanishes: radtan without coefficients) and each ``std_i g_i``.
    """
    x = p_cam[:, :2] / p_cam[:, 2:3]
    focal = np.array([camera.fx, camera.fy])
    shift = OFFSET_NODES * spread.center_offset_px / focal  # (Q, 2) normalised
    shifted = (x[None, :, :] - shift[:, None, :]).reshape(-1, 2)
    model, coefficients = camera.distortion, len(camera.dist)
    at_shifted = _distortion_basis(model, coefficients, shifted).reshape(1 + coefficients, len(shift), -1, 2)
    differences = at_shifted - _distortion_basis(model, coefficients, x)[:, None]  # (1 + D, Q, N, 2)
    differences[0] += shift[:, None, :]
    fields = [differences[0] + np.tensordot(camera.dist, differences[1:], axes=1)] if _has_mean_misfit(camera) else []
    fields += [std * differences[1 + i] for i, std in enumerate(spread.coefficient_std) if std > 0]
    weighted = np.stack(fields) * np.sqrt(OFFSET_WEIGHTS)[None, :, None, None] * focal  # (F, Q, N, 2) [px]
    return weighted.reshape(-1, len(x) * 2).T


def _has_mean_misfit(camera: CameraModel) -> bool:
    """Whether the guess's own lens, decentred, misfits (all but radtan without coefficients)."""
    return camera.distortion != "radtan" or bool(np.any(camera.dist))


def _distortion_basis(distortion: str, coefficients: int, y: np.ndarray) -> np.ndarray:
    """(1 + D, N, 2): the distortion without coefficients ``d_0(y)``, then each unit coefficient's ``b_i(y)``."""
    if distortion == "radtan":
        return _radtan_basis(y)
    cameras = _basis_cameras(distortion, coefficients)
    d0 = cameras[0].distort(y)
    return np.stack([d0, *(camera.distort(y) - d0 for camera in cameras[1:])])


@functools.cache  # one set per camera model, asked for at every frame
def _basis_cameras(distortion: str, coefficients: int) -> tuple[CameraModel, ...]:
    """Cameras of the model without distortion coefficients, then with each unit coefficient (only ``distort`` used)."""
    return tuple(
        CameraModel(distortion=distortion, width=2, height=2, fx=1.0, fy=1.0, cx=0.5, cy=0.5, dist=dist)
        for dist in np.vstack([np.zeros(coefficients), np.eye(coefficients)])
    )


def _radtan_basis(y: np.ndarray) -> np.ndarray:
    """``_distortion_basis`` of radtan in one pass: the same floats as ``CameraModel.distort`` with unit coefficients
    (its expression with the zero terms dropped, which add exact zeros)."""
    u, v = y[:, 0], y[:, 1]
    uu, vv, uv = u * u, v * v, u * v
    r2 = uu + vv
    out = np.zeros((5, len(y), 2))
    out[0, :, 0], out[0, :, 1] = u, v
    out[1, :, 0], out[1, :, 1] = u * (1.0 + r2) - u, v * (1.0 + r2) - v  # k1
    r4 = 1.0 + r2 * r2
    out[2, :, 0], out[2, :, 1] = u * r4 - u, v * r4 - v  # k2
    out[3, :, 0], out[3, :, 1] = (u + 2.0 * uv) - u, (v + (r2 + 2.0 * vv)) - v  # p1
    out[4, :, 0], out[4, :, 1] = (u + (r2 + 2.0 * uu)) - u, (v + 2.0 * uv) - v  # p2
    return out


def _check_lens_spread(task: str, camera: CameraModel) -> None:
    if task == "extrinsic":
        raise ValueError(
            "a lens spread needs the camera's parameters in the problem: the extrinsic task takes the intrinsics as "
            "given; declare it for the intrinsic or joint task only"
        )
    if camera.is_wide_angle or camera.distortion_center_offset.any():
        raise ValueError(
            f"a lens spread applies to a centred pinhole camera model (radtan, equidistant), not to {camera.distortion}"
            " or a guess with its own offset; leave it out"
        )


def _schur(block: np.ndarray, keep: int) -> np.ndarray:
    """Information of the first ``keep`` variables with the rest marginalised."""
    return _eliminated(block[:keep, :keep], block[:keep, keep:], block[keep:, keep:])


def _marginalise(block: np.ndarray, start: int, stop: int) -> np.ndarray:
    """``block`` with the variables in ``[start, stop)`` marginalised out (the rest keeps its order)."""
    keep = np.r_[np.arange(start), np.arange(stop, block.shape[0])]
    gone = np.arange(start, stop)
    return _eliminated(block[np.ix_(keep, keep)], block[np.ix_(keep, gone)], block[np.ix_(gone, gone)])


def _eliminated(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``a - b c^-1 b^T``: what the kept variables know once those of ``c`` are marginalised. A variable no factor
    has touched yet (an all-zero row of ``c``: the first state's velocity until an IMU factor links it to the next)
    knows nothing and shares nothing, so it is dropped instead of making ``c`` singular."""
    touched = np.flatnonzero(np.any(c != 0.0, axis=1))
    b, c = b[:, touched], c[np.ix_(touched, touched)]
    return a - b @ np.linalg.solve(c, b.T)


# ------------------------------------------------------------------------------------------------ the MDP's view
CHI_DIMS = {"focal": 2, "principal_point": 2, "distortion": 2, "rotation": 3, "translation": 3, "time_offset": 1}
FEATURE_DECADES = 4.0  # a state feature spans 1e-2 .. 1e2 times the tolerance (0.5: at the tolerance)


@functools.cache  # a handful of (group, confidence) pairs, asked for at every env step
def quantile_factor(group: str, confidence: float) -> float:
    """The error norm's ``confidence`` quantile over its 1-sigma: the chi quantile of the group's dimension."""
    return float(np.sqrt(chi2.ppf(confidence, CHI_DIMS[group])))


def tolerance_ratios(sigmas: dict[str, float], tolerances, confidence: float) -> dict[str, float]:
    """Per group: its predicted error quantile over its tolerance (<= 1: the group is done).

    Every group must be within tolerance at once with probability ``confidence``, so each group's
    quantile is taken at ``1 - (1 - confidence) / groups`` (Bonferroni): measured on 50 sensors of
    the intrinsic task, per-group quantiles at 0.9 left 23 of 31 stopped episodes within every
    tolerance, 74 %.
    """
    per_group = 1.0 - (1.0 - confidence) / max(len(sigmas), 1)
    return {g: quantile_factor(g, per_group) * s / tolerances.of(g) for g, s in sigmas.items()}


def axis_ratios(axis_sigmas: np.ndarray, task: str, tolerances, confidence: float) -> np.ndarray:
    """(6,) each camera axis's predicted error quantile over its group's tolerance (``axis_sigmas``: rotation [deg]
    then translation [mm], ``InformationTracker.axis_sigmas``), at the quantile ``tolerance_ratios`` takes for the
    group: so the largest axis's ratio is the group's where the covariance's worst direction is an axis."""
    per_group = 1.0 - (1.0 - confidence) / len(TASK_GROUPS[task])
    scale = [quantile_factor(g, per_group) / tolerances.of(g) for g in ("rotation", "translation")]
    return np.asarray(axis_sigmas, dtype=float) * np.repeat(scale, 3)


def feature(ratios: np.ndarray) -> np.ndarray:
    """Ratios on the state's scale: 0.5 at the tolerance, ``1 / FEATURE_DECADES`` per decade, clipped to [0, 1]."""
    return np.clip(0.5 + np.log10(np.maximum(ratios, 1e-12)) / FEATURE_DECADES, 0.0, 1.0)


def features(ratios: dict[str, float]) -> np.ndarray:
    """(6,) a value in [0, 1] per group of ``GROUPS``: 0.5 at the tolerance, 0 for a group the task leaves out."""
    out = np.zeros(len(GROUPS))
    for k, group in enumerate(GROUPS):
        if group in ratios:
            out[k] = feature(np.array(ratios[group]))
    return out


def excess(ratios: dict[str, float], cap: float = np.inf, floor: float = 1.0, outside_weight: float = 1.0) -> float:
    """Sum over groups of ``ln(clip(ratio, floor, cap) / floor)``: e-folds the predicted errors still have to
    shrink by to reach ``floor`` times their tolerances, those above the tolerance (ratio > 1) counted
    ``outside_weight`` times."""
    inside = sum(np.log(min(max(r, floor), 1.0) / floor) for r in ratios.values())
    outside = sum(np.log(min(max(r, 1.0), cap)) for r in ratios.values())
    return float(inside + outside_weight * outside)

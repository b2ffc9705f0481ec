"""Whether the data support a calibration result, judged after the solve: a result fails only on evidence.

A solve can converge on data it cannot explain. A gyro logged in deg/s but read as rad/s (a slow
motion passes the readers' range check) still gives a "converged" solve, with an extrinsic and time
offset that mean nothing. What proves a wrong setting, each measured independently of the solve's
weighting:

- ``gyro_scale``: the gyro's rotation over the camera's between frames (57.3 for deg/s read as rad/s);
- ``accel_scale``: the accelerometer's median magnitude over gravity (about 1/9.81 for g read as m/s^2);
- ``board_scale``: the camera's accelerations over the IMU's (the ratio of the board's declared size to
  its true one: a wrong tag size or square);
- ``implausibilities``: a solve that did not converge or never left its initial guess, a principal point
  outside the image, and corners that the model cannot fit (a reprojection rms far above any detector's
  noise: a wrong target or lens model).

IMU residuals above the declared noise are no such evidence: real IMUs routinely show 5-15x their
datasheet densities (vibration, unmodelled effects), and calibrators take the declared values as given.
They are a warning (``vical.calib.solve.visual_inertial``), never a failure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from vical.calib.result import CalibrationResult, FramePoses
from vical.calib.solve.imu_integration import cumulative_angle, interpolate
from vical.calib.solve.initialization import frame_poses
from vical.calib.solve.model_fit import MISFIT_FAIL_PX
from vical.calib.solve.observations import collect_observations
from vical.calib.solve.time_alignment import rotation_increments
from vical.calib.solve.visual_inertial import GRAVITY_MAGNITUDE
from vical.data import CameraFrames, ImuSamples, Target, seconds_since
from vical.geometry import CameraModel

NOISE_LIMIT = 5.0  # reprojection rms over the declared (or assumed) corner noise beyond which corners do not fit
# A sensor scale this far from 1 (either way) is a wrong setting: units are 9.81x or 57.3x off, and a wrong
# tag size is off by far more than the few percent that lever arms and noise leave in a closed-form ratio.
SCALE_LIMIT = 1.5
BOARD_SCALE_SIGMAS = 4.0  # ... and the board's scale must be that many of its standard errors away from 1
ACCEL_WINDOW = 0.15  # [s] step of the second differences of the camera positions (board scale)
LEVER_ARM_PRIOR = 0.1  # [m] 1-sigma of each component of the camera-IMU lever arm in the board scale's fit
# [px] the corner noise assumed when none is declared: sub-pixel corner detectors stay well below it.
DEFAULT_PIXEL_SIGMA = 1.0
DEG_PER_RAD = 180.0 / np.pi


def implausibilities(
    result: CalibrationResult, initial_T_cam_imu: np.ndarray | None = None, pixel_sigma: float | None = None
) -> list[str]:
    """What makes ``result`` untrustworthy, in plain words; empty when nothing does.

    Args:
        result: a calibration result.
        initial_T_cam_imu: (4, 4) the extrinsic guess the solve started from (its translation is
            what the solve moves; the rotation starts from a closed form).
        pixel_sigma: [px] the declared corner noise (``DEFAULT_PIXEL_SIGMA`` when None).
    """
    found = []
    if result.status != "converged":
        found.append(
            f"the solve did not converge in {result.iterations} iterations (the views constrain the parameters too "
            "weakly: add views tilted 30-60 deg, near the image's corners, at several distances)"
        )
    camera = result.camera
    if not camera.principal_point_in_image:
        found.append(
            f"the principal point ({camera.cx:.1f}, {camera.cy:.1f}) px lies outside the {camera.width} x "
            f"{camera.height} image"
        )
    guessed = initial_T_cam_imu is not None and result.T_cam_imu is not None
    if result.iterations == 0:
        found.append("the solve made no step from its initial guess (0 iterations)")
    elif guessed and np.array_equal(result.T_cam_imu[:3, 3], np.asarray(initial_T_cam_imu)[:3, 3]):
        found.append("the camera-IMU translation is exactly its initial guess")
    if result.lens_misfit is not None and result.lens_misfit[0] > MISFIT_FAIL_PX:
        field, noise = result.lens_misfit
        found.append(
            f"the corners keep a systematic {field:.2f} px per axis from where the {camera.distortion} camera puts "
            f"them, the same in every view (beside {noise:.2f} px of corner noise): the camera model or its "
            "intrinsics do not describe the lens"
        )
    sigma = DEFAULT_PIXEL_SIGMA if pixel_sigma is None else pixel_sigma
    rms = result.reprojection.rms
    if rms > NOISE_LIMIT * sigma:
        how = "declared" if pixel_sigma is not None else "assumed"
        found.append(f"the reprojection rms {rms:.3g} px is {rms / sigma:.3g}x the {how} corner noise {sigma:g} px")
    return found


def posed_frames(frames: CameraFrames, target: Target, camera: CameraModel) -> FramePoses:
    """The PnP poses of ``frames`` (for a result that carries none: ``CalibrationResult.frame_poses``)."""
    observations = collect_observations(frames, target)
    poses = frame_poses(camera, observations)
    keys = sorted(poses)
    return FramePoses(
        np.array([observations[k].t_ns for k in keys], dtype=np.int64),
        np.array([poses[k][0] for k in keys]).reshape(-1, 4, 4),
    )


def gyro_scale(posed: FramePoses, imu: ImuSamples) -> float | None:
    """How many times the camera's rotation the gyro reads, between frames (ratio of summed angles).

    Independent of any solve: the camera's rotation increments come from PnP with ``camera``, the
    gyro's from integrating it over the same intervals (a time offset of a few frames' worth does not
    change sums of magnitudes). About 57.3 (degrees per radian) for a gyro logged in deg/s and read
    as rad/s, about 1/57.3 the other way round, about 1 otherwise; None when too few frames have a pose.
    """
    if len(posed.t_ns) < 2 or len(imu) < 2:
        return None
    t0 = imu.t[0]
    times = seconds_since(posed.t_ns, t0)
    increments = rotation_increments(times, np.transpose(posed.T_cam_target[:, :3, :3], (0, 2, 1)))
    t_imu = seconds_since(imu.t, t0)
    inside = (increments.t_start >= t_imu[0]) & (increments.t_end <= t_imu[-1])
    if not inside.any():
        return None
    angle = cumulative_angle(t_imu, imu.gyro)
    gyro = interpolate(t_imu, angle, increments.t_end[inside]) - interpolate(t_imu, angle, increments.t_start[inside])
    seen = float(np.linalg.norm(increments.theta_cam[inside], axis=1).sum())
    return float(np.linalg.norm(gyro, axis=1).sum()) / seen if seen > 0 else None


def likely_gyro_unit(scale: float | None, declared: str) -> str | None:
    """The gyro unit (``"deg/s"`` or ``"rad/s"``) a ``gyro_scale`` points to when it is not ``declared``, else None."""
    if scale is None:
        return None
    other, expected = ("deg/s", DEG_PER_RAD) if declared == "rad/s" else ("rad/s", 1.0 / DEG_PER_RAD)
    return other if abs(np.log(scale / expected)) < np.log(2.0) else None


def accel_scale(imu: ImuSamples, gravity_magnitude: float = GRAVITY_MAGNITUDE) -> float | None:
    """The accelerometer's median magnitude over gravity: about 1 in m/s^2, 1/9.81 for readings in g read as
    m/s^2, 9.81 the other way round (hand-held and robot motions average to gravity); None without samples."""
    if len(imu) == 0:
        return None
    return float(np.median(np.linalg.norm(imu.accel, axis=1))) / gravity_magnitude


def likely_accel_unit(scale: float | None, declared: str) -> str | None:
    """The accelerometer unit (``"g"`` or ``"m/s^2"``) an ``accel_scale`` points to when it is not ``declared``."""
    if scale is None:
        return None
    if declared == "m/s^2":
        return "g" if scale < 1 / SCALE_LIMIT else None
    return "m/s^2" if scale > SCALE_LIMIT else None


@dataclass(frozen=True)
class BoardScale:
    """The board's declared size over its true size, measured twice (``board_scale``), each as (scale, sigma), or
    None where the data do not determine it.

    Attributes:
        centre: from the camera centre's own accelerations (the lever arm left out: a camera turning about
            itself, the IMU swinging around it, reads low).
        lever_arm: with the camera-IMU lever arm fitted too, under a prior of a rig's size (over a few
            seconds of coupled turning and moving it still trades off against the scale, and reads low).
    """

    centre: tuple[float, float] | None
    lever_arm: tuple[float, float] | None


def board_scale(posed: FramePoses, imu: ImuSamples, R_cam_imu: np.ndarray, time_offset: float) -> BoardScale | None:
    """How many times the camera's accelerations are the IMU's: the board's declared size over its true size.

    Independent of the solve (a wrong board size makes the solved lever arm meaningless): the camera's
    positions come from the PnP poses, and their divided second differences over ``ACCEL_WINDOW`` equal the
    IMU's accelerations averaged with the same hat-shaped weights, less the lever arm's share (the second
    difference of ``R_target_cam r``), all times the scale: ``a_cam = s (R f + g) - D2[R_target_cam] (s r)``,
    fitted by linear least squares without the lever arm and with it (``BoardScale``). A board given 10 %
    too large makes every camera position, and so every acceleration, 10 % too large.

    Returns:
        None with too few evenly spaced posed frames or too little motion.
    """
    if len(posed.t_ns) < 10 or len(imu) < 2:
        return None
    t0 = imu.t[0]
    times = seconds_since(posed.t_ns, t0) + time_offset
    T_target_cam = np.linalg.inv(posed.T_cam_target)
    positions, R_target_cam = T_target_cam[:, :3, 3], T_target_cam[:, :3, :3]
    t_imu = seconds_since(imu.t, t0)
    before, centre, after = _difference_triples(times, t_imu)
    if len(centre) < 10:
        return None
    t0s, t1s, t2s = times[before], times[centre], times[after]
    camera_accel = _second_difference(positions, before, centre, after, t0s, t1s, t2s)
    rotation_accel = _second_difference(R_target_cam, before, centre, after, t0s, t1s, t2s)  # (C, 3, 3)
    spanned = (t_imu > times[0]) & (t_imu < times[-1])  # every kernel's samples lie between the first and last frame
    rotations = _imu_rotations(times, R_target_cam @ R_cam_imu, t_imu, imu.gyro)
    force = rotations[spanned].apply(imu.accel[spanned])  # the specific force in the board frame
    imu_accel = _kernel_average(t_imu[spanned], force, t0s, t1s, t2s)
    # The camera's second differences carry the noise (PnP's, amplified); the IMU's averages are the regressor,
    # nearly exact, so the fit is not attenuated by noise in its regressor.
    A = np.zeros((len(centre), 3, 7))
    A[:, :, 0] = imu_accel
    A[:, :, 1:4] = np.eye(3)
    A[:, :, 4:] = rotation_accel
    A, b = A.reshape(-1, 7), camera_accel.reshape(-1)
    return BoardScale(_scale_fit(A[:, :4], b), _scale_fit(*_lever_arm_prior(A, b)))


def _imu_rotations(times: np.ndarray, R_target_imu: np.ndarray, t_imu: np.ndarray, gyro: np.ndarray) -> Rotation:
    """The IMU's orientation in the board frame at every sample: the last frame's (``R_target_imu`` (F, 3, 3) at
    ``times`` (F,)) carried on by the gyro. Interpolated between the frames instead, a hand's tremor (0.3 deg at
    8-12 Hz, seen by a 10 Hz camera as a slow wobble) tilted gravity by as much as the motion's own accelerations,
    and the board's scale read 0.77 on true poses (the gyro's bias turns it by well under a degree between frames).
    """
    steps = Rotation.from_rotvec(gyro[:-1] * np.diff(t_imu)[:, None])
    turned = [Rotation.identity()]
    for step in steps:  # the IMU's orientation since the first sample (its drift cancels between near instants)
        turned.append(turned[-1] * step)
    turned = Rotation.concatenate(turned)
    at_frames = Slerp(t_imu, turned)(np.clip(times, t_imu[0], t_imu[-1]))
    last = np.clip(np.searchsorted(times, t_imu, side="right") - 1, 0, len(times) - 1)
    return Rotation.from_matrix(R_target_imu[last]) * at_frames[last].inv() * turned


def _lever_arm_prior(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The system with a prior of ``LEVER_ARM_PRIOR`` on each component of the (scaled) lever arm, weighted
    against the unconstrained fit's residual noise: over a few seconds of coupled turning and moving, the
    lever arm alone would trade off against the scale."""
    noise = float(np.sqrt(np.mean((b - A @ np.linalg.lstsq(A, b, rcond=None)[0]) ** 2)))
    prior = np.zeros((3, A.shape[1]))
    prior[:, 4:] = np.eye(3) * noise / LEVER_ARM_PRIOR
    return np.vstack([A, prior]), np.concatenate([b, np.zeros(3)])


def _scale_fit(A: np.ndarray, b: np.ndarray) -> tuple[float, float] | None:
    """The first unknown of ``A x = b`` (least squares) and its standard error; None when it is not positive or
    not determined to within half of itself."""
    solution, *_ = np.linalg.lstsq(A, b, rcond=None)
    residual = b - A @ solution
    covariance = np.linalg.pinv(A.T @ A) * float(residual @ residual) / max(len(b) - A.shape[1], 1)
    scale, sigma = float(solution[0]), float(np.sqrt(covariance[0, 0]))
    return (scale, sigma) if scale > 0 and sigma < 0.5 * scale else None


def _second_difference(x: np.ndarray, before, centre, after, t0: np.ndarray, t1: np.ndarray, t2: np.ndarray):
    """Divided second differences of ``x`` (F, ...) over the triples ``(before, centre, after)`` at ``t0 < t1 < t2``."""
    shape = (-1,) + (1,) * (x.ndim - 1)
    ahead = (x[after] - x[centre]) / (t2 - t1).reshape(shape)
    behind = (x[centre] - x[before]) / (t1 - t0).reshape(shape)
    return 2 * (ahead - behind) / (t2 - t0).reshape(shape)


def _difference_triples(times: np.ndarray, t_imu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices (before, centre, after) of posed frames about ``ACCEL_WINDOW`` [s] apart, inside the IMU's span.

    Gaps (frames without a pose) are skipped: both steps must be within half and one and a half times the
    window."""
    step = max(1, round(ACCEL_WINDOW / float(np.median(np.diff(times)))))
    centre = np.arange(step, len(times) - step)
    before, after = centre - step, centre + step
    d1, d2 = times[centre] - times[before], times[after] - times[centre]
    even = (np.minimum(d1, d2) > 0.5 * ACCEL_WINDOW) & (np.maximum(d1, d2) < 1.5 * ACCEL_WINDOW)
    inside = (times[before] >= t_imu[0]) & (times[after] <= t_imu[-1])
    keep = even & inside
    return before[keep], centre[keep], after[keep]


def _kernel_average(t: np.ndarray, x: np.ndarray, t0: np.ndarray, t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    """(C, 3) samples ``x`` (N, 3) at ``t`` (N,) averaged with the kernel of each second difference over the
    instants ``t0 < t1 < t2`` [s]: a divided second difference of positions is the acceleration weighted by the
    hat function rising from ``t0`` to ``t1`` and falling to ``t2``.

    Exactly, for the samples' linear interpolant: the same divided second difference of its double integral
    (``_double_integral``). A sum of the hat's weights at the samples misses the hat between its ends and the
    samples nearest them, which matters where the hat leaves little of a strong signal (a hand's tremor: 4 m/s^2 at
    8-12 Hz, 3 % of it through a 0.15 s hat).
    """
    p0, p1, p2 = (_double_integral(t, x)(instants) for instants in (t0, t1, t2))
    ahead, behind = (p2 - p1) / (t2 - t1)[:, None], (p1 - p0) / (t1 - t0)[:, None]
    return 2 * (ahead - behind) / (t2 - t0)[:, None]


def _double_integral(t: np.ndarray, x: np.ndarray):
    """``p(tau)`` (C,) -> (C, 3): the double integral from ``t[0]`` of the linear interpolant of ``x`` (N, 3) at
    ``t`` (N,), exact (a cubic between samples)."""
    dt = np.diff(t)[:, None]
    slope = np.diff(x, axis=0) / dt
    velocity = np.concatenate([np.zeros((1, 3)), np.cumsum(x[:-1] * dt + slope * dt**2 / 2, axis=0)])
    position = np.concatenate([np.zeros((1, 3)), np.cumsum(velocity[:-1] * dt + x[:-1] * dt**2 / 2 + slope * dt**3 / 6,
                                                            axis=0)])  # fmt: skip
    slope = np.vstack([slope, np.zeros((1, 3))])

    def p(tau: np.ndarray) -> np.ndarray:
        k = np.clip(np.searchsorted(t, tau, side="right") - 1, 0, len(t) - 1)
        u = (tau - t[k])[:, None]
        return position[k] + velocity[k] * u + x[k] * u**2 / 2 + slope[k] * u**3 / 6

    return p


def wrong_board_scale(found: BoardScale | None) -> bool:
    """Whether a ``board_scale`` proves the board's size wrong: the camera centre's ratio beyond ``SCALE_LIMIT``
    and ``BOARD_SCALE_SIGMAS`` of its error from 1, and the ratio with the lever arm fitted beyond the limit's
    square root on the same side (either can read low on honest data, for its own reason; a wrong size moves
    both)."""
    if found is None or found.centre is None or found.lever_arm is None:
        return False
    (scale, sigma), (with_arm, _) = found.centre, found.lever_arm
    side = np.sign(np.log(scale))
    far = abs(np.log(scale)) > np.log(SCALE_LIMIT) and abs(scale - 1.0) > BOARD_SCALE_SIGMAS * sigma
    return bool(far and side * np.log(with_arm) > 0.5 * np.log(SCALE_LIMIT))

"""Whether the data support a calibration result, judged after the solve.

A solve can converge on data it cannot explain. A gyro logged in deg/s but read as rad/s (a slow
motion passes the readers' range check) gives IMU residuals about 1e5 times the declared noise;
the solve weighs each sensor by the noise its residuals show, so it still reports "converged" and
an extrinsic and time offset that mean nothing. ``implausibilities`` names what gives such a result
away: residuals far above the declared noise (``CalibrationResult.imu_noise_scale`` for the IMU,
the reprojection rms for the corners), and a solve that never left its initial guess.
``gyro_scale`` and ``likely_gyro_unit`` tell a gyro unit error apart from other causes.
"""

from __future__ import annotations

import numpy as np

from vical.calib.imu_integration import cumulative_angle, interpolate
from vical.calib.initialization import frame_poses
from vical.calib.observations import collect_observations
from vical.calib.result import CalibrationResult
from vical.calib.time_alignment import rotation_increments
from vical.data import CameraFrames, ImuSamples, Target, seconds_since
from vical.geometry import CameraModel

NOISE_LIMIT = 5.0  # residual noise over declared noise beyond which a result is not trusted
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
    guessed = initial_T_cam_imu is not None and result.T_cam_imu is not None
    if result.iterations == 0:
        found.append("the solve made no step from its initial guess (0 iterations)")
    elif guessed and np.array_equal(result.T_cam_imu[:3, 3], np.asarray(initial_T_cam_imu)[:3, 3]):
        found.append("the camera-IMU translation is exactly its initial guess")
    scale = result.imu_noise_scale
    if scale is not None and scale > NOISE_LIMIT:
        gyro, accel = result.imu_residuals.gyro_stats.rms, result.imu_residuals.accel_stats.rms
        found.append(
            f"the IMU residuals (gyro rms {gyro:.3g} rad/s, accelerometer rms {accel:.3g} m/s^2) show a noise "
            f"{scale:.3g}x the declared densities"
        )
    sigma = DEFAULT_PIXEL_SIGMA if pixel_sigma is None else pixel_sigma
    rms = result.reprojection.rms
    if rms > NOISE_LIMIT * sigma:
        how = "declared" if pixel_sigma is not None else "assumed"
        found.append(f"the reprojection rms {rms:.3g} px is {rms / sigma:.3g}x the {how} corner noise {sigma:g} px")
    return found


def gyro_scale(frames: CameraFrames, imu: ImuSamples, target: Target, camera: CameraModel) -> float | None:
    """How many times the camera's rotation the gyro reads, between frames (ratio of summed angles).

    Independent of any solve: the camera's rotation increments come from PnP with ``camera``, the
    gyro's from integrating it over the same intervals (a time offset of a few frames' worth does not
    change sums of magnitudes). About 57.3 (degrees per radian) for a gyro logged in deg/s and read
    as rad/s, about 1/57.3 the other way round, about 1 otherwise; None when too few frames have a pose.
    """
    observations = collect_observations(frames, target)
    poses = frame_poses(camera, observations)
    if len(poses) < 2 or len(imu) < 2:
        return None
    keys = sorted(poses)
    t0 = imu.t[0]
    times = seconds_since(np.array([observations[k].t_ns for k in keys]), t0)
    increments = rotation_increments(times, np.array([poses[k][0][:3, :3].T for k in keys]))
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

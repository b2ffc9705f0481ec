"""Calibration errors against ground truth: the paper's relative errors and absolute errors users read.

Relative errors follow the authors' evaluation code (see ``docs/calibration.md``):

- intrinsic [%]: ``100 ||[fx, fy, cx, cy] - gt|| / ||gt||`` (distortion excluded);
- extrinsic [%]: ``100 sqrt(||R - R_gt||_F^2 + ||t - t_gt||^2) / sqrt(||R_gt||_F^2 + ||t_gt||^2)`` of
  ``T_cam_imu`` (the relative error of the 12-vector ``[vec R, t]``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from vical.calib.result import CalibrationResult
from vical.data import SensorTruth
from vical.geometry import CameraModel, transform_error


def intrinsic_relative_error(camera: CameraModel, truth: CameraModel) -> float:
    """The paper's intrinsic error [%] of ``[fx, fy, cx, cy]``."""
    return float(100.0 * np.linalg.norm(camera.intrinsics - truth.intrinsics) / np.linalg.norm(truth.intrinsics))


def extrinsic_relative_error(T_cam_imu: np.ndarray, T_true: np.ndarray) -> float:
    """The paper's extrinsic error [%]: relative error of the 12-vector ``[vec R, t]`` of ``T_cam_imu`` (4, 4)."""
    d_R = np.linalg.norm(T_cam_imu[:3, :3] - T_true[:3, :3])
    d_t = np.linalg.norm(T_cam_imu[:3, 3] - T_true[:3, 3])
    scale = np.sqrt(np.linalg.norm(T_true[:3, :3]) ** 2 + np.linalg.norm(T_true[:3, 3]) ** 2)
    return float(100.0 * np.hypot(d_R, d_t) / scale)


@dataclass(frozen=True)
class CalibrationErrors:
    """Errors of one calibration against the truth (None where the task did not estimate it).

    Attributes:
        intrinsic_pct: the paper's intrinsic error [%].
        intrinsic_abs_px: (4,) |fx, fy, cx, cy| errors [px].
        extrinsic_pct: the paper's extrinsic error [%].
        rotation_deg: rotation error of ``T_cam_imu`` [deg].
        translation_mm: translation error of ``T_cam_imu`` [mm].
        time_offset_ms: |time offset error| [ms].
    """

    intrinsic_pct: float
    intrinsic_abs_px: np.ndarray
    extrinsic_pct: float | None = None
    rotation_deg: float | None = None
    translation_mm: float | None = None
    time_offset_ms: float | None = None

    def to_dict(self) -> dict:
        d = asdict(self)
        d["intrinsic_abs_px"] = [float(v) for v in self.intrinsic_abs_px]
        return d


def calibration_errors(result: CalibrationResult, truth: SensorTruth) -> CalibrationErrors:
    """Relative and absolute errors of ``result`` against ``truth``."""
    return parameter_errors(result.camera, result.T_cam_imu, result.time_offset, truth)


def parameter_errors(
    camera: CameraModel, T_cam_imu: np.ndarray | None, time_offset: float | None, truth: SensorTruth
) -> CalibrationErrors:
    """Relative and absolute errors of estimated parameters against ``truth``.

    Args:
        camera: estimated camera.
        T_cam_imu: (4, 4) estimated extrinsic, or None when not estimated (then no extrinsic errors).
        time_offset: estimated time offset [s], or None when not estimated.
        truth: the sensor's true parameters.
    """
    intrinsic_pct = intrinsic_relative_error(camera, truth.camera)
    intrinsic_abs = np.abs(camera.intrinsics - truth.camera.intrinsics)
    if T_cam_imu is None:
        return CalibrationErrors(intrinsic_pct, intrinsic_abs)
    rot, trans = transform_error(T_cam_imu, truth.T_cam_imu)
    dt = None if time_offset is None else abs(time_offset - truth.time_offset) * 1e3
    return CalibrationErrors(
        intrinsic_pct,
        intrinsic_abs,
        extrinsic_relative_error(T_cam_imu, truth.T_cam_imu),
        float(np.rad2deg(rot)),
        float(trans * 1e3),
        dt,
    )


def corner_ray(camera: CameraModel) -> np.ndarray:
    """(1, 3) the ray ``camera`` images at its image corner; for a wide-angle lens whose image circle leaves the
    corner dark, at the right edge: where the distortion moves a point farthest."""
    if camera.is_wide_angle:
        right = camera.width - 1.0
        rays, seen = camera.bearings(np.array([[right, camera.height - 1.0], [right, camera.cy]]))
        return rays[:1] if seen[0] else rays[1:]
    return np.array([[(camera.width - 1 - camera.cx) / camera.fx, (camera.height - 1 - camera.cy) / camera.fy, 1.0]])


def group_errors_px(camera: CameraModel, truth: CameraModel) -> dict[str, float | None]:
    """The intrinsic parameter groups' errors [px]: ``focal`` (norm of the fx, fy errors), ``principal_point``
    (cx, cy) and ``distortion``: how far the estimated coefficients move the image corner from where the true
    ones image its ray, with the true focal lengths and principal point (None for another camera model)."""
    d = camera.intrinsics[:4] - truth.intrinsics[:4]
    distortion = None
    if camera.distortion == truth.distortion:
        ray = corner_ray(truth)
        true_uv, _ = truth.project(ray)
        estimated_uv, seen = truth.with_intrinsics(truth.fx, truth.fy, truth.cx, truth.cy, camera.dist).project(ray)
        distortion = float(np.linalg.norm(estimated_uv[0] - true_uv[0])) if seen[0] else float("inf")
    focal, principal_point = float(np.hypot(d[0], d[1])), float(np.hypot(d[2], d[3]))
    return {"focal": focal, "principal_point": principal_point, "distortion": distortion}


def image_differences_px(camera: CameraModel, truth: CameraModel, step: float = 8.0) -> np.ndarray:
    """Distances (N,) [px] between where ``truth`` and ``camera`` image the same rays, over the image.

    Every ``step``-th pixel of the image that ``truth`` unprojects is taken back to its ray and projected with
    ``camera`` (inf where ``camera`` cannot): the error a calibrated camera makes in pixels, whatever its
    parameters (models differ).
    """
    u, v = np.meshgrid(np.arange(0.0, truth.width, step), np.arange(0.0, truth.height, step))
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    rays, ok = truth.bearings(pixels)
    uv, projected = camera.project(rays[ok])
    return np.where(projected, np.linalg.norm(uv - pixels[ok], axis=1), np.inf)

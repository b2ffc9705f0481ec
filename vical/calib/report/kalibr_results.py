"""``results-imucam.txt``: a camera-IMU calibration in the layout of Kalibr's results file, and whether it is good.

The sections are Kalibr's: the normalised residuals (each residual whitened by its declared noise, the norm of the
whitened vector), the raw ones, each camera's two transforms and time shift, a rig's baselines, the gravity in the
target frame, the cameras' (with the target's) and the IMU's configuration, each field named as Kalibr's
``printResultTxt`` names it. vical's IMU residuals are per IMU factor, the mean rate over each interval
between two camera states, where Kalibr's are per IMU sample: a mean over ``dt`` has the sigma ``density /
sqrt(dt)``, so the normalised values read the same, and the raw ones are smaller than Kalibr's by the square root
of the samples in an interval. "Is this a good result" judges the reprojection rms, the IMU by the noise its residuals
measure over their degrees of freedom (``CalibrationResult.imu_noise_scale``; not by the normalised means, which a
fit makes smaller than the noise: 0.4-0.5 x a whitened 3-vector's 1.60 on a simulated IMU exactly as declared) and
the parameters the data leave weak, and names what to do where they fail. (The corners' noise is measured from their
residuals, so their normalised mean is ~1.25, a whitened 2-vector's, by construction.)
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from vical.calib.result import CalibrationResult
from vical.data import ImuNoise, Target
from vical.geometry import invert_transform
from vical.io.kalibr import kalibr_intrinsics

# The judged band: normalised residuals within these factors of a sensor-as-declared's are "as declared".
AS_DECLARED = (0.5, 2.0)
SUBPIXEL = 1.0  # [px] a raw reprojection rms above this says the corners or the lens model are poor


def _norms(residuals: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.asarray(residuals, dtype=float), axis=1)


def _stats(norms: np.ndarray) -> str:
    return f"mean {norms.mean():.6g}, median {np.median(norms):.6g}, std: {norms.std():.6g}"


def normalised_residuals(result: CalibrationResult) -> dict[str, np.ndarray]:
    """The norms of the reprojection, gyroscope and accelerometer residuals whitened by the declared noise."""
    imu = result.imu_residuals
    return {
        "reprojection": _norms(result.reprojection_residuals) / result.pixel_sigma,
        "gyroscope": _norms((imu.gyro_measured - imu.gyro_predicted) / imu.gyro_sigma[:, None]),
        "accelerometer": _norms((imu.accel_measured - imu.accel_predicted) / imu.accel_sigma[:, None]),
    }


def raw_residuals(result: CalibrationResult) -> dict[str, np.ndarray]:
    imu = result.imu_residuals
    return {
        "reprojection": _norms(result.reprojection_residuals),
        "gyroscope": _norms(imu.gyro_measured - imu.gyro_predicted),
        "accelerometer": _norms(imu.accel_measured - imu.accel_predicted),
    }


def _matrix(T: np.ndarray) -> list[str]:
    rows = [" ".join(f"{v: .8f}" for v in row) for row in np.asarray(T)]
    return ["[[" + rows[0] + "]", *(" [" + r + "]" for r in rows[1:-1]), " [" + rows[-1] + "]]"]


def _residual_sections(results: dict[str, CalibrationResult]) -> list[str]:
    imu_result = next(iter(results.values()))  # the IMU's residuals: one IMU, the same in every camera's result
    normalised = {n: normalised_residuals(r) for n, r in results.items()}
    raw = {n: raw_residuals(r) for n, r in results.items()}
    lines = ["Normalized Residuals", "----------------------------"]
    lines += [f"Reprojection error ({n}):".ljust(36) + _stats(normalised[n]["reprojection"]) for n in results]
    first = next(iter(results))
    lines += [
        "Gyroscope error (imu0):".ljust(36) + _stats(normalised[first]["gyroscope"]),
        "Accelerometer error (imu0):".ljust(36) + _stats(normalised[first]["accelerometer"]),
        "",
        "Residuals",
        "----------------------------",
    ]
    lines += [f"Reprojection error ({n}) [px]:".ljust(40) + _stats(raw[n]["reprojection"]) for n in results]
    lines += [
        "Gyroscope error (imu0) [rad/s]:".ljust(40) + _stats(raw[first]["gyroscope"]),
        "Accelerometer error (imu0) [m/s^2]:".ljust(40) + _stats(raw[first]["accelerometer"]),
        f"  (IMU errors per IMU factor: the mean over each of {len(imu_result.imu_residuals.dt)} intervals, "
        f"{np.median(imu_result.imu_residuals.dt) * 1e3:.0f} ms median)",
    ]
    return lines


def _transform_sections(results: dict[str, CalibrationResult]) -> list[str]:
    lines = []
    for name, result in results.items():
        lines += [
            "",
            f"Transformation ({name}):",
            "-----------------------",
            f"T_ci:  (imu0 to {name}): ",
            *_matrix(result.T_cam_imu),
            "",
            f"T_ic:  ({name} to imu0): ",
            *_matrix(invert_transform(result.T_cam_imu)),
            "",
            f"timeshift {name} to imu0: [s] (t_imu = t_cam + shift)",
            repr(float(result.time_offset)),
        ]
    lines += _baseline_section(results)
    gravity = next(iter(results.values())).gravity_target
    if gravity is not None:
        lines += ["", "Gravity vector in target coords: [m/s^2]", "[" + " ".join(f"{g:.8f}" for g in gravity) + "]"]
    return lines


# The projection coefficients Kalibr's intrinsics put before [fu, fv, pu, pv], by camera model, as its report
# names them (Kalibr names omni's and ds's; eucm's follow them).
PROJECTION_NAMES = {"pinhole": (), "omni": ("Omni xi",), "ds": ("DS xi", "DS alpha"),
                    "eucm": ("EUCM alpha", "EUCM beta")}  # fmt: skip


def _camera_lines(result: CalibrationResult) -> list[str]:
    """A camera's configuration as Kalibr prints it: model, focal length, principal point, the projection's own
    coefficients, distortion."""
    k = kalibr_intrinsics(result.camera)
    names = PROJECTION_NAMES[k["camera_model"]]
    coeffs, (fu, fv, pu, pv) = k["intrinsics"][: len(names)], k["intrinsics"][len(names) :]
    return [
        f"  Camera model: {k['camera_model']}",
        f"  Focal length: [{fu!r}, {fv!r}]",
        f"  Principal point: [{pu!r}, {pv!r}]",
        *(f"  {name}: {value!r}" for name, value in zip(names, coeffs, strict=True)),
        f"  Distortion model: {k['distortion_model']}",
        f"  Distortion coefficients: [{', '.join(repr(v) for v in k['distortion_coeffs'])}]",
    ]


def _target_lines(target: Target) -> list[str]:
    """The target as Kalibr prints it under each camera."""
    rows, cols, row_spacing = int(target.rows), int(target.cols), float(target.row_spacing)
    if target.kind == "aprilgrid":
        gap = row_spacing * float(target.tag_spacing)
        return ["  Type: aprilgrid", "  Tags: ", f"    Rows: {rows}", f"    Cols: {cols}",
                f"    Size: {row_spacing!r} [m]", f"    Spacing {gap!r} [m]"]  # fmt: skip
    return ["  Type: checkerboard", "  Rows", f"    Count: {rows}", f"    Distance: {row_spacing!r} [m]",
            "  Cols", f"    Count: {cols}", f"    Distance: {float(target.col_spacing)!r} [m]"]  # fmt: skip


def _baseline_section(results: dict[str, CalibrationResult]) -> list[str]:
    """A rig's baselines as Kalibr prints them: each camera to the next (``T_cn_cnm1``) and its length."""
    names = list(results)
    if len(names) < 2:
        return []
    lines = ["", "Baselines:", "----------"]
    for before, name in itertools.pairwise(names):
        T = results[name].T_cam_imu @ invert_transform(results[before].T_cam_imu)
        norm = float(np.linalg.norm(T[:3, 3]))
        lines += [f"Baseline ({before} to {name}): ", *_matrix(T), f"baseline norm:  {norm!r} [m]", ""]
    return lines


def _camera_configuration(results: dict[str, CalibrationResult], target: Target) -> list[str]:
    lines = ["", "", "Calibration configuration", "========================="]
    for name, result in results.items():
        lines += ["", name, "-----", *_camera_lines(result), *_target_lines(target)]
    return lines


def _imu_configuration(noise: ImuNoise, imu_model: str) -> list[str]:
    root_rate = math.sqrt(noise.rate_hz)
    return [
        "",
        "",
        "IMU configuration",
        "=================",
        "",
        "IMU0:",
        " ----------------------------",
        f"  Model: {imu_model}",
        f"  Update rate: {noise.rate_hz}",
        "  Accelerometer:",
        f"    Noise density: {noise.accel_noise_density:.6g} ",
        f"    Noise density (discrete): {noise.accel_noise_density * root_rate:.6g} ",
        f"    Random walk: {noise.accel_random_walk:.6g}",
        "  Gyroscope:",
        f"    Noise density: {noise.gyro_noise_density:.6g}",
        f"    Noise density (discrete): {noise.gyro_noise_density * root_rate:.6g} ",
        f"    Random walk: {noise.gyro_random_walk:.6g}",
    ]


def _judged(scale: float) -> str:
    """The verdict on the IMU noise its residuals measure, ``scale`` x the declared densities."""
    low, high = AS_DECLARED
    what = f"IMU noise measured from its residuals: {scale:.2f} x the declared"
    if scale > high:
        return (
            f"  [check] {what}: the IMU is noisier than declared (vibration, an imu.yaml of another IMU, an unmodelled "
            "scale or time offset): measure it at rest with vical-imu-noise, or calibrate with --imu-model "
            "scale-misalignment"
        )
    if scale < low:
        return f"  [check] {what}: the IMU is quieter than declared, so the sigmas are conservative"
    return f"  [ok] {what}"


def good_result_lines(results: dict[str, CalibrationResult]) -> list[str]:
    """The verdicts of "Is this a good result", each with the threshold it judges by."""
    low, high = AS_DECLARED
    lines = ["", "", "Is this a good result", "====================="]
    lines.append(
        f"Thresholds: a reprojection rms of at most {SUBPIXEL:g} px; the IMU's noise measured from its residuals "
        f"within {low:g}-{high:g} x the declared densities; every parameter determined by the data."
    )
    for name, result in results.items():
        rms = result.reprojection.rms
        verdict = "[ok]" if rms <= SUBPIXEL else "[check]"
        advice = (
            "" if rms <= SUBPIXEL else ": blurred or misdetected corners, or a lens model that does not fit (--model)"
        )
        lines.append(f"  {verdict} reprojection rms of {name}: {rms:.3f} px{advice}")
        lines.append(
            f"    (its corners' noise, measured from the residuals, weights them: {result.pixel_sigma:.3f} px)"
        )
    first = next(iter(results.values()))
    if first.imu_noise_scale is not None:  # the residuals over their degrees of freedom, not the normalised means
        lines.append(_judged(first.imu_noise_scale))
    weak = [w.name for r in results.values() for w in r.weak_parameters]
    lines.append(
        f"  [check] weakly determined: {', '.join(dict.fromkeys(weak))} (results.txt says what motion helps)"
        if weak
        else "  [ok] every parameter determined by the data"
    )
    return lines


def kalibr_results_text(results: dict[str, CalibrationResult], target: Target, imu_model: str = "calibrated") -> str:
    """``results-imucam.txt`` of a camera-IMU calibration of the cameras ``results`` (by name, cam0 first), judged
    by the IMU noise the calibration was given."""
    sections = [
        "Calibration results",
        "===================",
        *_residual_sections(results),
        *_transform_sections(results),
        *_camera_configuration(results, target),
        *_imu_configuration(next(iter(results.values())).imu_residuals.noise, imu_model),
        *good_result_lines(results),
    ]
    return "\n".join(sections) + "\n"

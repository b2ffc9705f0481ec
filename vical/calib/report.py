"""Human-readable outputs of a calibration: summary table, results text and plots (PNG + PDF).

All files are written atomically (temporary sibling + ``os.replace``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure  # no pyplot: no global backend state, no display needed

from vical.calib.metrics import CalibrationErrors
from vical.calib.result import CalibrationResult, ResidualStats
from vical.calib.uncertainty import IMU_INTRINSIC_THRESHOLDS
from vical.geometry import matrix_to_euler
from vical.io.atomic import atomic_file, write_text_atomic

UNCERTAINTY_NOTE = (
    "1-sigma values come from the factor graph's marginal covariance, each sensor weighted by the noise its "
    "residuals show, and widened wherever the parameters move more with the data over time than the noise "
    "model explains (cluster-robust covariance over 0.5 s windows). Errors that stay the same over the whole "
    "recording (a wrong board size, a bent board) are not covered."
)


def _value_line(name: str, value: float, sigma: float | None, unit: str, scale: float = 1.0) -> str:
    s = "" if sigma is None else f" +- {sigma * scale:.4g}"
    return f"  {name:<12} {value * scale:>14.6f}{s} {unit}"


def _camera_lines(result: CalibrationResult) -> list[str]:
    cam, sig = result.camera, result.sigmas
    lines = [f"camera: pinhole-{cam.distortion} {cam.width} x {cam.height}"]
    for name, value in zip(["fx", "fy", "cx", "cy"], cam.intrinsics, strict=True):
        lines.append(_value_line(name, value, sig.get(name), "px"))
    names = ["k1", "k2", "p1", "p2"] if cam.distortion == "radtan" else ["k1", "k2", "k3", "k4"]
    lines += [_value_line(n, v, sig.get(n), "") for n, v in zip(names, cam.dist, strict=True)]
    return lines


def _extrinsic_lines(result: CalibrationResult) -> list[str]:
    if result.T_cam_imu is None:
        return []
    sig = result.sigmas
    T = result.T_cam_imu
    lines = ["T_cam_imu (maps IMU points into the camera frame):"]
    lines += ["  [" + ", ".join(f"{v: .8f}" for v in row) + "]" for row in T]
    rpy = np.rad2deg(matrix_to_euler(T[:3, :3]))
    lines.append(f"  roll/pitch/yaw [deg]: {rpy[0]:.4f} {rpy[1]:.4f} {rpy[2]:.4f}")
    rot_sigma = np.rad2deg([sig["rot_x"], sig["rot_y"], sig["rot_z"]])
    lines.append(
        f"  rotation 1-sigma about camera x/y/z [deg]: {rot_sigma[0]:.4f} {rot_sigma[1]:.4f} {rot_sigma[2]:.4f}"
    )
    for axis, value in zip("xyz", T[:3, 3], strict=True):
        lines.append(_value_line(f"t_{axis}", value, sig[f"t_{axis}"], "mm", 1e3))
    lines.append(_value_line("time offset", result.time_offset, sig["time_offset"], "ms (t_imu = t_cam + offset)", 1e3))
    lines.append("  gyro bias [rad/s]: " + " ".join(f"{v:.6f}" for v in result.gyro_bias))
    lines.append("  accel bias [m/s^2]: " + " ".join(f"{v:.5f}" for v in result.accel_bias))
    return lines


def _imu_intrinsic_lines(result: CalibrationResult) -> list[str]:
    """The IMU intrinsics with their 1-sigma (scales in %, misalignments in deg) when they were estimated."""
    sig = result.sigmas
    names = [n for n in result.parameter_names if n in IMU_INTRINSIC_THRESHOLDS]
    if not names:
        return []
    values = dict(zip(result.parameter_names, result.estimate, strict=True))
    lines = ["IMU intrinsics (Kalibr's scale-misalignment model; scale - 1 in %, angles in deg):"]
    for n in names:
        scale, unit = _intrinsic_unit(n)
        lines.append(_value_line(n, values[n], sig[n], unit, scale))
    return lines


def _intrinsic_unit(name: str) -> tuple[float, str]:
    """(factor, unit) in which an IMU intrinsic parameter is printed."""
    if "_scale_" in name:
        return 100.0, "%"
    if name.startswith("g_sens_"):
        return 1.0, "(rad/s)/(m/s^2)"
    return float(np.rad2deg(1.0)), "deg"


def _stats_line(name: str, stats: ResidualStats, unit: str) -> str:
    return (
        f"  {name:<14} mean {stats.mean:.4g}  median {stats.median:.4g}  std {stats.std:.4g}  "
        f"rms {stats.rms:.4g}  max {stats.max:.4g} {unit} (n={stats.count})"
    )


def _quality_lines(result: CalibrationResult) -> list[str]:
    lines = ["residuals:", _stats_line("reprojection", result.reprojection, "px")]
    if result.imu_residuals is not None:
        lines.append(_stats_line("gyro", result.imu_residuals.gyro_stats, "rad/s"))
        lines.append(_stats_line("accel", result.imu_residuals.accel_stats, "m/s^2"))
    lines.append(f"  corner noise used: {result.pixel_sigma:.4g} px")
    if result.imu_noise_scale is not None:
        lines.append(f"  IMU noise from its residuals: {result.imu_noise_scale:.3g} x the declared densities")
    lines.append(
        f"solver: {result.status}, {result.iterations} iterations, {result.solve_time:.3f} s, "
        f"{result.num_frames} frames"
    )
    return lines


def _weak_lines(result: CalibrationResult) -> list[str]:
    if not result.weak_parameters:
        return ["weakly observed parameters: none"]
    lines = ["weakly observed parameters (weakest first):"]
    for w in result.weak_parameters:
        lines.append(f"  {w.name}: 1-sigma {w.sigma:.4g} > {w.threshold:.4g} -> {w.hint}")
    return lines


def _correlation_lines(result: CalibrationResult) -> list[str]:
    if not result.correlations:
        return []
    lines = ["strongest correlations between parameter groups (|rho| near 1: the data hardly tell them apart):"]
    lines += [f"  {c.a:<12} {c.b:<12} rho {c.rho:+.3f}" for c in result.correlations]
    return lines


def _error_lines(errors: CalibrationErrors | None) -> list[str]:
    if errors is None:
        return []
    abs_px = " ".join(f"{v:.3f}" for v in errors.intrinsic_abs_px)
    lines = ["errors against the truth:", f"  intrinsic {errors.intrinsic_pct:.4f} %  |fx fy cx cy| {abs_px} px"]
    if errors.extrinsic_pct is not None:
        lines.append(
            f"  extrinsic {errors.extrinsic_pct:.4f} %  rotation {errors.rotation_deg:.4f} deg  "
            f"translation {errors.translation_mm:.3f} mm"
        )
    if errors.time_offset_ms is not None:
        lines.append(f"  time offset {errors.time_offset_ms:.4f} ms")
    return lines


def results_text(result: CalibrationResult, errors: CalibrationErrors | None = None, failure: str | None = None) -> str:
    """The full results text (Kalibr's ``results-*.txt`` in spirit): estimates +- 1-sigma and quality.

    ``failure``: why the result must not be used; it heads the text.
    """
    sections = [
        [f"FAILED: {failure}", "The estimates below are kept for diagnosis; do not use them."] if failure else [],
        [f"vical calibration results: task {result.task}"],
        _camera_lines(result),
        _extrinsic_lines(result),
        _imu_intrinsic_lines(result),
        _quality_lines(result),
        _weak_lines(result),
        _correlation_lines(result),
        _error_lines(errors),
        ["warnings:", *[f"  {w}" for w in result.warnings]] if result.warnings else [],
        ["note: " + UNCERTAINTY_NOTE],
    ]
    return "\n\n".join("\n".join(s) for s in sections if s) + "\n"


def summary_table(result: CalibrationResult, errors: CalibrationErrors | None = None) -> str:
    """A short table for the terminal: key estimates, their 1-sigma and (when known) errors."""
    sig = result.sigmas
    rows = [("task", result.task, ""), ("fx fy [px]", f"{result.camera.fx:.3f} {result.camera.fy:.3f}", "")]
    rows.append(("cx cy [px]", f"{result.camera.cx:.3f} {result.camera.cy:.3f}", ""))
    if "fx" in sig:
        rows[-2] = (rows[-2][0], rows[-2][1], f"+- {sig['fx']:.3f} {sig['fy']:.3f}")
        rows[-1] = (rows[-1][0], rows[-1][1], f"+- {sig['cx']:.3f} {sig['cy']:.3f}")
    if result.T_cam_imu is not None:
        t = result.T_cam_imu[:3, 3] * 1e3
        st = [sig[f"t_{a}"] * 1e3 for a in "xyz"]
        rows.append(("t_cam_imu [mm]", f"{t[0]:.2f} {t[1]:.2f} {t[2]:.2f}", f"+- {st[0]:.2f} {st[1]:.2f} {st[2]:.2f}"))
        rows.append(("time offset [ms]", f"{result.time_offset * 1e3:.3f}", f"+- {sig['time_offset'] * 1e3:.3f}"))
    rows.append(("reprojection rms [px]", f"{result.reprojection.rms:.4f}", ""))
    rows.append(("solve time [s]", f"{result.solve_time:.3f}", f"{result.iterations} iterations, {result.status}"))
    if errors is not None:
        rows.append(("intrinsic error [%]", f"{errors.intrinsic_pct:.4f}", ""))
        if errors.extrinsic_pct is not None:
            rows.append(("extrinsic error [%]", f"{errors.extrinsic_pct:.4f}", ""))
            rows.append(("rot / trans error", f"{errors.rotation_deg:.4f} deg / {errors.translation_mm:.3f} mm", ""))
        if errors.time_offset_ms is not None:
            rows.append(("time offset error [ms]", f"{errors.time_offset_ms:.4f}", ""))
    width = max(len(r[0]) for r in rows)
    return "\n".join(f"{a:<{width}}  {b:<28} {c}".rstrip() for a, b, c in rows)


def write_results_text(
    path: str | os.PathLike,
    result: CalibrationResult,
    errors: CalibrationErrors | None = None,
    failure: str | None = None,
) -> None:
    """Write ``results_text`` to ``path`` atomically."""
    write_text_atomic(path, results_text(result, errors, failure))


def _reprojection_figure(result: CalibrationResult):
    fig = Figure(figsize=(11, 4.5))
    ax0, ax1 = fig.subplots(1, 2)
    r = result.reprojection_residuals
    ax0.scatter(r[:, 0], r[:, 1], s=2, alpha=0.4)
    ax0.set_xlabel("u residual [px]")
    ax0.set_ylabel("v residual [px]")
    ax0.set_title(f"reprojection errors (rms {result.reprojection.rms:.3f} px)")
    ax0.set_aspect("equal", adjustable="datalim")
    ax1.plot(result.reprojection_frames, np.linalg.norm(r, axis=1), ".", ms=2)
    ax1.set_xlabel("frame index")
    ax1.set_ylabel("|residual| [px]")
    ax1.set_title("reprojection error per corner over the recording")
    fig.tight_layout()
    return fig


def _imu_figure(result: CalibrationResult):
    imu = result.imu_residuals
    fig = Figure(figsize=(11, 7))
    axes = fig.subplots(3, 2, sharex=True)
    pairs = [(imu.gyro_measured, imu.gyro_predicted, "gyro [rad/s]"), (imu.accel_measured, imu.accel_predicted, "")]
    for col, (meas, pred, unit) in enumerate(pairs):
        unit = unit or "accel [m/s^2]"
        for i, axis in enumerate("xyz"):
            ax = axes[i, col]
            ax.plot(imu.t, meas[:, i], lw=0.8, label="measured")
            ax.plot(imu.t, pred[:, i], lw=0.8, ls="--", label="predicted from states")
            ax.set_ylabel(f"{unit.split()[0]} {axis} {unit.split()[1]}")
        axes[-1, col].set_xlabel("time [s]")
    axes[0, 0].legend(loc="upper right", fontsize=7)
    fig.suptitle("IMU: mean rates per state interval, measured vs predicted")
    fig.tight_layout()
    return fig


def _save_png(fig, path: Path) -> None:
    with atomic_file(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)


def write_report(directory: str | os.PathLike, result: CalibrationResult) -> list[Path]:
    """Plots of the residuals as PNGs and one ``report.pdf`` in ``directory``; returns the written paths."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    figures = {"reprojection": _reprojection_figure(result)}
    if result.imu_residuals is not None and len(result.imu_residuals.t):
        figures["imu"] = _imu_figure(result)
    written = []
    for name, fig in figures.items():
        _save_png(fig, directory / f"{name}.png")
        written.append(directory / f"{name}.png")
    with atomic_file(directory / "report.pdf") as tmp, PdfPages(tmp) as pdf:
        for fig in figures.values():
            pdf.savefig(fig)
    written.append(directory / "report.pdf")
    return written

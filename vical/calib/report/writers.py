"""Human-readable outputs of a calibration: summary table, results text, the frames' CSV, the report (PDF + PNGs).

All files are written atomically (temporary sibling + ``os.replace``).
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from vical.calib.frame_log import REASONS, FrameLog, short_reason
from vical.calib.metrics import CalibrationErrors
from vical.calib.result import CalibrationResult, ResidualStats, WeakParameter
from vical.calib.solve.uncertainty import IMU_INTRINSIC_THRESHOLDS
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
    model = cam.distortion if cam.is_wide_angle else f"pinhole-{cam.distortion}"
    lines = [f"camera: {model} {cam.width} x {cam.height}"]
    for name, value in zip(["fx", "fy", "cx", "cy"], cam.intrinsics, strict=True):
        lines.append(_value_line(name, value, sig.get(name), "px"))
    lines += [_value_line(n, v, sig.get(n), "") for n, v in zip(cam.coefficient_names, cam.dist, strict=True)]
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
    if result.line_delay is not None:  # estimated (with its sigma) or the known one the solve used
        unit = "us/row (a rolling shutter: row v exposed line_delay * v after the timestamp)"
        lines.append(_value_line("line delay", result.line_delay, sig.get("line_delay"), unit, 1e6))
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


# (factor, unit) in which the report prints each camera-IMU parameter (its value in the parameter's unit x factor).
_DISPLAY_UNITS = {
    **dict.fromkeys(("fx", "fy", "cx", "cy"), (1.0, "px")),
    **dict.fromkeys(("rot_x", "rot_y", "rot_z"), (float(np.rad2deg(1.0)), "deg")),
    **dict.fromkeys(("t_x", "t_y", "t_z"), (1e3, "mm")),
    "time_offset": (1e3, "ms"),
    "line_delay": (1e6, "us/row"),
    **dict.fromkeys(("bg_x", "bg_y", "bg_z"), (1.0, "rad/s")),
    **dict.fromkeys(("ba_x", "ba_y", "ba_z"), (1.0, "m/s^2")),
}


def display_unit(name: str) -> tuple[float, str]:
    """(factor, unit) in which a parameter is printed, as on the report's first page: pixels, mm, ms, deg, the IMU
    intrinsics' % and deg; distortion coefficients have no unit (``""``)."""
    if name in _DISPLAY_UNITS:
        return _DISPLAY_UNITS[name]
    if name in IMU_INTRINSIC_THRESHOLDS:
        return _intrinsic_unit(name)
    return 1.0, ""


def weak_sigma_text(weak: WeakParameter, with_threshold: bool = False) -> str:
    """``1-sigma 6.33 mm`` (``... > 2 mm`` with the threshold) in the parameter's printed unit (``display_unit``)."""
    scale, unit = display_unit(weak.name)
    unit = f" {unit}" if unit else ""
    text = f"1-sigma {weak.sigma * scale:.3g}{unit}"
    return text + (f" > {weak.threshold * scale:.3g}{unit}" if with_threshold else "")


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


def _frame_lines(log: FrameLog | None, limit: int = 20) -> list[str]:
    """The frame counts, then the frames not used (or trimmed) by reason, each named by file or timestamp [ns]."""
    if log is None:
        return []
    lines = ["frames: " + log.summary()]
    for reason in log.counts():
        labels = [r.label for r in log.records if r.reason == reason]
        more = f", ... ({len(labels) - limit} more)" if len(labels) > limit else ""
        lines.append(f"  {short_reason(reason)} ({len(labels)}): {', '.join(labels[:limit])}{more}")
    return lines


FRAMES_CSV_HEADER = [
    "index", "timestamp_ns", "file", "corners_found", "corners_used", "status", "reason", "explanation",
]  # fmt: skip


def frames_csv(log: FrameLog) -> str:
    """Every frame as a CSV row: index, timestamp [ns], file, corners found and used, status, reason code and text."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(FRAMES_CSV_HEADER)
    for r in log.records:
        status = "used" if r.used else "not used"
        writer.writerow([r.index, r.t_ns, r.name or "", r.found, r.used, status, r.reason, REASONS.get(r.reason, "")])
    return out.getvalue()


def write_frames_csv(path: str | os.PathLike, log: FrameLog) -> None:
    """Write ``frames_csv`` to ``path`` atomically."""
    write_text_atomic(path, frames_csv(log))


def _weak_lines(result: CalibrationResult) -> list[str]:
    if not result.weak_parameters:
        return ["weakly observed parameters: none"]
    lines = ["weakly observed parameters (weakest first):"]
    for w in result.weak_parameters:
        lines.append(f"  {w.name}: {weak_sigma_text(w, with_threshold=True)} -> {w.hint}")
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
        _frame_lines(result.frame_log),
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
    if result.line_delay is not None:
        sigma = f"+- {sig['line_delay'] * 1e6:.3f}" if "line_delay" in sig else "(given)"
        rows.append(("line delay [us/row]", f"{result.line_delay * 1e6:.3f}", sigma))
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


def _summary_lines(result: CalibrationResult, errors: CalibrationErrors | None, failure: str | None) -> list[str]:
    """The report's first page: the estimates with their 1-sigma, the errors against the truth, quality and frames."""
    sections = [
        [f"FAILED: {failure}", "The estimates below are kept for diagnosis; do not use them."] if failure else [],
        [f"task {result.task}"],
        _camera_lines(result),
        _extrinsic_lines(result),
        _error_lines(errors),
        _quality_lines(result),
        ["frames: " + result.frame_log.summary()] if result.frame_log is not None else [],
    ]
    return [line for section in sections if section for line in [*section, ""]]


def _notes_lines(result: CalibrationResult) -> list[str]:
    """The report's last page: warnings, weak parameters, correlations, the frames not used, what 1-sigma means."""
    sections = [
        ["warnings:", *[f"  {w}" for w in result.warnings]] if result.warnings else ["warnings: none"],
        _weak_lines(result),
        _correlation_lines(result),
        _frame_lines(result.frame_log),
        ["note: " + UNCERTAINTY_NOTE],
    ]
    return [line for section in sections if section for line in [*section, ""]]


def report_pages(result: CalibrationResult, errors: CalibrationErrors | None = None, failure: str | None = None):
    """The report's pages in order (``matplotlib.figure.Figure``): parameters, reprojection residuals, coverage,
    frames, then for camera-IMU tasks the IMU's measured and predicted rates, its residuals, its biases, its sample
    spacing and the time offset, and last the notes."""
    from vical.calib.report import figures

    pages = figures.text_pages(f"vical calibration report: {result.task}", _summary_lines(result, errors, failure))
    pages.append(figures.reprojection_page(result))
    if result.reprojection_pixels is not None and len(result.reprojection_pixels) >= 3:
        pages.append(figures.coverage_page(result))
    if result.frame_log is not None:
        pages.append(figures.frames_page(result.frame_log))
    if result.imu_residuals is not None and len(result.imu_residuals.t):
        pages += [figures.imu_page(result), figures.imu_residual_page(result), figures.imu_bias_page(result)]
    if result.time_offset_trace is not None:
        pages += [figures.imu_spacing_page(result.time_offset_trace.t_imu), figures.time_offset_page(result)]
    return pages + figures.text_pages("Notes", _notes_lines(result))


def _save_png(fig, path: Path) -> None:
    with atomic_file(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)


def write_report(
    directory: str | os.PathLike,
    result: CalibrationResult,
    errors: CalibrationErrors | None = None,
    failure: str | None = None,
) -> list[Path]:
    """``report.pdf`` (``report_pages``) and the residual plots as PNGs in ``directory``; returns the written paths."""
    # matplotlib takes half a second to import: a run without plots (--no-report, the text outputs) never does
    from matplotlib.backends.backend_pdf import PdfPages

    from vical.calib.report import figures

    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    pngs = {"reprojection": figures.reprojection_page(result)}
    if result.imu_residuals is not None and len(result.imu_residuals.t):
        pngs["imu"] = figures.imu_page(result)
    written = []
    for name, fig in pngs.items():
        _save_png(fig, directory / f"{name}.png")
        written.append(directory / f"{name}.png")
    with atomic_file(directory / "report.pdf") as tmp, PdfPages(tmp) as pdf:
        for fig in report_pages(result, errors, failure):
            pdf.savefig(fig)
    written.append(directory / "report.pdf")
    return written

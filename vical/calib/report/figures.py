"""The figures of a calibration report: one ``matplotlib.figure.Figure`` per page (no pyplot state).

Pages are A4 landscape. Large recordings are drawn from an evenly spaced subset of the corners
(``MAX_POINTS``, ``MAX_ARROWS``): every statistic in a title is computed from all of them.
"""

from __future__ import annotations

import textwrap

import cv2
import numpy as np
from matplotlib.figure import Figure  # no pyplot: no global backend state, no display needed
from matplotlib.patches import Circle, Rectangle

from vical.calib.frame_log import REASONS, FrameLog, short_reason
from vical.calib.result import CalibrationResult
from vical.data import NS_PER_S

PAGE = (11.69, 8.27)  # [in] A4 landscape
TEXT_COLUMNS = 120  # characters per line of a text page (monospace, 9 pt)
TEXT_ROWS = 50  # lines per text page
MAX_POINTS = 20_000  # corners drawn in a scatter plot
MAX_ARROWS = 1_500  # residual arrows drawn over the image
HEAT_CELLS = 32  # cells across the image in the coverage heat map
RESIDUAL_CELLS = 16  # cells across the image in the residual map (more corners per cell: a steadier mean)
REASON_COLOURS = {
    "no_board": "0.75",
    "too_few_corners": "tab:orange",
    "thinned": "tab:purple",
    "no_pose": "tab:brown",
    "outlier": "tab:red",
    "outside_imu": "tab:pink",
    "unpaired": "tab:cyan",
}


def _spread(n: int, limit: int) -> np.ndarray:
    """Indices of at most ``limit`` of ``n`` items, evenly spaced."""
    return np.arange(0, n, max(1, -(-n // limit)))


def text_pages(title: str, lines: list[str]) -> list[Figure]:
    """Pages of monospace text (long lines wrapped), ``title`` at the top of each."""
    wrapped = [w for line in lines for w in (textwrap.wrap(line, TEXT_COLUMNS, subsequent_indent="    ") or [""])]
    pages = []
    for start in range(0, max(len(wrapped), 1), TEXT_ROWS):
        fig = Figure(figsize=PAGE)
        fig.text(0.04, 0.96, title, fontsize=14, weight="bold", va="top")
        body = "\n".join(wrapped[start : start + TEXT_ROWS])
        fig.text(0.04, 0.91, body, family="monospace", fontsize=9, va="top", linespacing=1.2)
        pages.append(fig)
    return pages


def _image_axes(ax, width: int, height: int, title: str) -> None:
    """Pixel axes of the image: u right, v down, the image border drawn."""
    ax.add_patch(Rectangle((-0.5, -0.5), width, height, fill=False, lw=0.8, ec="k"))
    ax.set_xlim(-0.05 * width, 1.05 * width)
    ax.set_ylim(1.05 * height, -0.05 * height)
    ax.set_aspect("equal")
    ax.set_xlabel("u [px]")
    ax.set_ylabel("v [px]")
    ax.set_title(title, fontsize=10)


def _seconds(log: FrameLog) -> np.ndarray:
    """(M,) [s] every input frame's time since the first frame."""
    t = np.array([r.t_ns for r in log.records], dtype=np.int64)
    return (t - t[0]).astype(np.float64) / NS_PER_S


def _per_frame(ax, result: CalibrationResult, norms: np.ndarray) -> None:
    """Mean residual norm of each used frame over time (over the frame index without a frame log); the worst named."""
    frames, inverse = np.unique(result.reprojection_frames, return_inverse=True)
    mean = np.bincount(inverse, weights=norms) / np.bincount(inverse)
    log = result.frame_log
    x = frames.astype(float) if log is None else _seconds(log)[frames]
    ax.plot(x, mean, ".", ms=4)
    worst = int(np.argmax(mean))
    label = str(frames[worst]) if log is None else log.records[int(frames[worst])].label
    ax.annotate(label, (x[worst], mean[worst]), fontsize=7, xytext=(4, 4), textcoords="offset points")
    ax.set_xlabel("frame index" if log is None else "time since the first frame [s]")
    ax.set_ylabel("mean |residual| of the frame [px]")
    ax.set_title("reprojection error per frame (the worst named)", fontsize=10)


def reprojection_page(result: CalibrationResult) -> Figure:
    """Residuals: their distribution, the mean per frame over time, as arrows and as magnitudes over the image."""
    r, pixels, cam = result.reprojection_residuals, result.reprojection_pixels, result.camera
    norms = np.linalg.norm(r, axis=1)
    fig = Figure(figsize=PAGE)
    (ax0, ax1), (ax2, ax3) = fig.subplots(2, 2)
    pick = _spread(len(r), MAX_POINTS)
    ax0.scatter(r[pick, 0], r[pick, 1], s=2, alpha=0.3, lw=0)
    ax0.add_patch(Circle((0, 0), 3 * result.pixel_sigma, fill=False, ec="tab:red", lw=0.8))
    ax0.set_aspect("equal", adjustable="datalim")
    ax0.set_xlabel("u residual [px]")
    ax0.set_ylabel("v residual [px]")
    ax0.set_title(f"residuals (rms {result.reprojection.rms:.3f} px; circle: 3 x the corner noise)", fontsize=10)
    _per_frame(ax1, result, norms)
    if pixels is None:
        ax2.axis("off")
        ax3.axis("off")
    else:
        _residual_arrows(fig, ax2, pixels, r, cam.width, cam.height)
        cells = _cell_means(pixels, norms, cam.width, cam.height)
        im = ax3.imshow(
            cells, extent=(-0.5, cam.width - 0.5, cam.height - 0.5, -0.5), cmap="magma", interpolation="nearest"
        )
        fig.colorbar(im, ax=ax3, label="mean |residual| [px]", shrink=0.8)
        _image_axes(ax3, cam.width, cam.height, "mean |residual| per image cell (blank: no corner)")
    fig.suptitle("Reprojection residuals (measured - predicted corner)", fontsize=13)
    fig.tight_layout()
    return fig


def _residual_arrows(fig: Figure, ax, pixels: np.ndarray, r: np.ndarray, width: int, height: int) -> None:
    """Residuals (N, 2) [px] as arrows from their corners (N, 2) [px], enlarged to be seen, coloured by length."""
    norms = np.linalg.norm(r, axis=1)
    pick = _spread(len(r), MAX_ARROWS)
    scale = 0.05 * width / max(float(np.percentile(norms, 99)), 1e-9)  # the 99th percentile: 5 % of the width
    u, v, du, dv = pixels[pick, 0], pixels[pick, 1], r[pick, 0] * scale, r[pick, 1] * scale
    arrows = ax.quiver(u, v, du, dv, norms[pick], angles="xy", scale_units="xy", scale=1, width=0.002, cmap="viridis")
    fig.colorbar(arrows, ax=ax, label="|residual| [px] (arrow colour)", shrink=0.8)
    _image_axes(ax, width, height, f"residuals over the image (arrows x {scale:.0f})")


def _cells(width: int, height: int, cols: int = HEAT_CELLS) -> tuple[np.ndarray, np.ndarray]:
    """Cell edges across (cols + 1,) and down (rows + 1,) the image [px], the cells about square."""
    rows = max(1, round(cols * height / width))
    return np.linspace(-0.5, width - 0.5, cols + 1), np.linspace(-0.5, height - 0.5, rows + 1)


def _cell_means(pixels: np.ndarray, values: np.ndarray, width: int, height: int) -> np.ndarray:
    """Mean of ``values`` (N,) over the corners in each image cell (rows, cols); NaN where none."""
    u_edges, v_edges = _cells(width, height, RESIDUAL_CELLS)
    total, _, _ = np.histogram2d(pixels[:, 1], pixels[:, 0], bins=(v_edges, u_edges), weights=values)
    count, _, _ = np.histogram2d(pixels[:, 1], pixels[:, 0], bins=(v_edges, u_edges))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, total / count, np.nan)


def coverage_page(result: CalibrationResult) -> Figure:
    """Where the used corners lie in the image: a count per cell, the convex hull of all of them."""
    cam, pixels = result.camera, result.reprojection_pixels
    fig = Figure(figsize=PAGE)
    ax = fig.subplots()
    u_edges, v_edges = _cells(cam.width, cam.height)
    count, _, _ = np.histogram2d(pixels[:, 1], pixels[:, 0], bins=(v_edges, u_edges))
    shown = np.where(count > 0, count, np.nan)
    im = ax.imshow(
        shown, extent=(-0.5, cam.width - 0.5, cam.height - 0.5, -0.5), cmap="viridis", interpolation="nearest"
    )
    fig.colorbar(im, ax=ax, label="corners per cell", shrink=0.8)
    hull = cv2.convexHull(pixels.astype(np.float32)).reshape(-1, 2)
    share = cv2.contourArea(hull) / (cam.width * cam.height)
    ax.plot(*np.vstack([hull, hull[:1]]).T, color="tab:red", lw=1.2, label=f"convex hull: {share:.0%} of the image")
    ax.legend(loc="upper right", fontsize=9)
    empty = np.mean(count == 0)
    _image_axes(ax, cam.width, cam.height, f"{len(pixels)} corners used; {empty:.0%} of the cells hold none (blank)")
    fig.suptitle("Coverage: where the board's corners were seen (the lens model is extrapolated in the blank cells)",
                 fontsize=13)  # fmt: skip
    return fig


def frames_page(log: FrameLog) -> Figure:
    """Corners found and used per frame over time, the frames not used coloured by reason, and the counts."""
    fig = Figure(figsize=PAGE)
    ax0, ax1 = fig.subplots(2, 1, gridspec_kw={"height_ratios": [3, 1.3]})
    seconds = _seconds(log)
    found = np.array([r.found for r in log.records])
    used = np.array([r.used for r in log.records])
    ax0.plot(seconds, found, color="0.6", lw=0.8, label="corners detected")
    ax0.plot(seconds, np.where(used > 0, used, np.nan), ".", ms=3, color="tab:green", label="corners used")
    for reason, colour in REASON_COLOURS.items():
        mask = np.array([r.reason == reason for r in log.records])
        if mask.any():
            ax0.plot(seconds[mask], found[mask], "x", ms=4, color=colour, label=f"not used: {short_reason(reason)}")
    ax0.set_ylim(0, 1.1 * max(int(found.max(initial=0)), 1))  # from 0: a steady count is a full line, not noise
    ax0.set_xlabel("time since the first frame [s]")
    ax0.set_ylabel("corners")
    ax0.legend(loc="lower right", fontsize=7, ncol=2)
    ax0.set_title(log.summary(), fontsize=8, wrap=True)
    counts = log.counts()
    rows = [["used with all corners", sum(1 for r in log.records if r.used and not r.reason)]]
    rows += [[REASONS[reason], n] for reason, n in counts.items()]
    ax1.axis("off")
    table = ax1.table(cellText=[[text, str(n)] for text, n in rows], colLabels=["frames", "count"],
                      colWidths=[0.7, 0.1], loc="upper center", cellLoc="left")  # fmt: skip
    table.auto_set_font_size(False)
    table.set_fontsize(8)
    fig.suptitle("Frames: detected, used and not used (frames.csv lists each with its file or timestamp)", fontsize=13)
    fig.tight_layout()
    return fig


def _per_axis_page(title: str, columns: list[tuple], draw) -> Figure:
    """A page of 3 x 2 axes over time: a column per sensor (``columns``: gyro, accel), a row per axis; ``draw(ax,
    column, i, axis)`` draws one; the first axes' legend, the title."""
    fig = Figure(figsize=PAGE)
    axes = fig.subplots(3, 2, sharex=True)
    for col, column in enumerate(columns):
        for i, axis in enumerate("xyz"):
            draw(axes[i, col], column, i, axis)
        axes[-1, col].set_xlabel("time [s]")
    axes[0, 0].legend(loc="upper right", fontsize=7)
    fig.suptitle(title, fontsize=13)
    fig.tight_layout()
    return fig


def imu_page(result: CalibrationResult) -> Figure:
    """Mean gyro rates and specific forces per state interval: measured against predicted from the states."""
    imu = result.imu_residuals

    def draw(ax, column, i, axis):
        meas, pred, name, unit = column
        ax.plot(imu.t, meas[:, i], lw=0.8, label="measured")
        ax.plot(imu.t, pred[:, i], lw=0.8, ls="--", label="predicted from the states")
        ax.set_ylabel(f"{name} {axis} [{unit}]")

    columns = [(imu.gyro_measured, imu.gyro_predicted, "gyro", "rad/s"),
               (imu.accel_measured, imu.accel_predicted, "accel", "m/s^2")]  # fmt: skip
    return _per_axis_page("IMU: mean rates per state interval, measured vs predicted", columns, draw)


BOUND_SIGMAS = 3.0  # the residual and bias pages' bounds: 3 sigma of the declared noise, as Kalibr plots them


def _within(values: np.ndarray, bound: np.ndarray) -> float:
    """[%] of ``values`` within +-``bound``."""
    return 100.0 * float(np.mean(np.abs(values) <= bound))


def _bounds(ax, t: np.ndarray, centre, bound: np.ndarray, label: str) -> None:
    """Dashed red lines at ``centre`` +- ``bound``, the upper one labelled."""
    for sign in (1, -1):
        ax.plot(t, centre + sign * bound, lw=0.8, ls="--", color="tab:red", label=label if sign > 0 else None)


def imu_residual_page(result: CalibrationResult) -> Figure:
    """Gyro and accelerometer residuals (measured - predicted) per axis over time, with their rms and the 3-sigma
    bounds of each interval's mean from the declared white noise (an IMU noisier than declared leaves them)."""
    imu = result.imu_residuals

    def draw(ax, column, i, axis):
        res, bound, name, unit = column
        ax.plot(imu.t, res[:, i], lw=0.7, color="tab:blue")
        _bounds(ax, imu.t, 0.0, bound, f"+-{BOUND_SIGMAS:g} sigma, declared noise")
        ax.axhline(0.0, color="0.5", lw=0.5)
        rms = float(np.sqrt(np.mean(res[:, i] ** 2)))
        inside = f"{_within(res[:, i], bound):.1f} % within {BOUND_SIGMAS:g} sigma"
        ax.set_title(f"{name} {axis}: rms {rms:.3g} {unit}, {inside}", fontsize=9)
        ax.set_ylabel(f"[{unit}]")

    columns = [
        (imu.gyro_measured - imu.gyro_predicted, BOUND_SIGMAS * imu.gyro_sigma, "gyro", "rad/s"),
        (imu.accel_measured - imu.accel_predicted, BOUND_SIGMAS * imu.accel_sigma, "accel", "m/s^2"),
    ]
    scale = "" if result.imu_noise_scale is None else f" (noise {result.imu_noise_scale:.2g} x the declared densities)"
    return _per_axis_page(f"IMU residuals: measured - predicted per state interval{scale}", columns, draw)


def imu_bias_page(result: CalibrationResult) -> Figure:
    """The estimated gyro and accelerometer biases over time (each state's), with the declared random walk's 3-sigma
    envelope around the first: a bias that leaves it drifts faster than declared."""
    imu = result.imu_residuals
    root_since = np.sqrt(imu.t - imu.t[0])

    def draw(ax, column, i, axis):
        bias, walk, name, unit = column
        envelope = BOUND_SIGMAS * walk * root_since
        ax.plot(imu.t, bias[:, i], lw=1.0, color="tab:blue", label="estimate")
        _bounds(ax, imu.t, bias[0, i], envelope, f"+-{BOUND_SIGMAS:g} sigma of the declared random walk")
        within = _within(bias[:, i] - bias[0, i], envelope)
        ax.set_title(f"{name} {axis}: {bias[0, i]:.4g} at the start, moving over {np.ptp(bias[:, i]):.3g} {unit}, "
                     f"{within:.0f} % within", fontsize=9)  # fmt: skip
        ax.set_ylabel(f"[{unit}]")

    columns = [(imu.gyro_bias, imu.noise.gyro_random_walk, "gyro bias", "rad/s"),
               (imu.accel_bias, imu.noise.accel_random_walk, "accel bias", "m/s^2")]  # fmt: skip
    return _per_axis_page("IMU biases over time: the estimate at each state", columns, draw)


GAP_FACTOR = 1.5  # an IMU sample spacing over this times the median is a gap (a dropped sample or more)


def imu_spacing_page(t_imu: np.ndarray) -> Figure:
    """The spacing of consecutive IMU samples over time and its histogram: dropped samples, jitter, a wrong rate."""
    spacing = np.diff(np.asarray(t_imu, dtype=float)) * 1e3  # [ms]
    median = float(np.median(spacing))
    gaps = spacing > GAP_FACTOR * median
    fig = Figure(figsize=PAGE)
    over_time, histogram = fig.subplots(2, 1, height_ratios=[1.4, 1])
    mid = 0.5 * (t_imu[1:] + t_imu[:-1])
    over_time.plot(mid, spacing, ".", ms=1.5, color="tab:blue")
    over_time.plot(mid[gaps], spacing[gaps], "o", ms=4, mfc="none", color="tab:red",
                   label=f"gaps: over {GAP_FACTOR:g} x the median")  # fmt: skip
    over_time.axhline(median, color="0.4", lw=0.8, ls="--", label=f"median {median:.3g} ms")
    over_time.set_xlabel("time [s]")
    over_time.set_ylabel("spacing [ms]")
    over_time.legend(loc="upper right", fontsize=8)
    over_time.ticklabel_format(axis="y", useOffset=False)  # stamps a few ns apart: the spacing itself, not +5
    histogram.hist(spacing, bins=60, color="tab:blue")
    histogram.ticklabel_format(axis="x", useOffset=False)
    histogram.set_yscale("log")
    histogram.set_xlabel("spacing [ms]")
    histogram.set_ylabel("intervals")
    jitter = float(np.std(spacing[~gaps])) * 1e3  # [us] the spacing's spread, gaps left out
    fig.suptitle(f"IMU sample spacing: {len(t_imu)} samples at {1e3 / median:.4g} Hz (the median), jitter "
                 f"{jitter:.1f} us, gaps over {GAP_FACTOR:g} x the median: {int(np.count_nonzero(gaps))}, the longest "
                 f"spacing {spacing.max():.3g} ms", fontsize=11)  # fmt: skip
    fig.tight_layout()
    return fig


def time_offset_page(result: CalibrationResult) -> Figure:
    """The camera's rotation rate against the gyro's, shifted by the offset, and the mismatch over offsets."""
    trace, tau = result.time_offset_trace, result.time_offset
    fig = Figure(figsize=PAGE)
    grid = fig.add_gridspec(4, 1, height_ratios=[1, 1, 1, 1.4])
    axes = [fig.add_subplot(grid[i]) for i in range(3)]
    for i, axis in enumerate("xyz"):
        ax = axes[i]
        ax.plot(trace.t_imu, trace.gyro[:, i], lw=0.6, color="tab:blue", label="gyro (bias removed)")
        ax.plot(trace.t_camera + tau, trace.omega_camera[:, i], ".", ms=2.5, color="tab:orange",
                label=f"camera (PnP), shifted by the time offset {tau * 1e3:.2f} ms")  # fmt: skip
        ax.set_ylabel(f"rate {axis} [rad/s]")
    axes[0].legend(loc="upper right", fontsize=7)
    axes[2].set_xlabel("time [s] (IMU clock, since the recording start)")
    ax = fig.add_subplot(grid[3])
    ax.plot(trace.shifts * 1e3, np.degrees(trace.mismatch), lw=1.0)
    ax.axvline(tau * 1e3, color="tab:red", lw=0.8, label=f"estimate {tau * 1e3:.2f} ms")
    ax.set_xlabel("time offset t_imu - t_cam [ms]")
    ax.set_ylabel("rms rotation mismatch [deg]")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title("camera vs gyro rotation between consecutive frames, for offsets around the estimate", fontsize=9)
    fig.suptitle("Time offset: the camera's rotation rate (in the IMU frame) against the gyro", fontsize=13)
    fig.tight_layout()
    return fig

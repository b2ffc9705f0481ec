"""Checks of a calibration's inputs: the IMU noise settings, the memory a recording needs, the image coverage."""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np

from vical.calib.errors import CalibrationError, CalibrationSettingError
from vical.calib.solve.observations import FrameObservation
from vical.data import ImuNoise

# Kalibr's imu.yaml keys of the noise settings, and the paper's IMU (a typical MEMS unit) for scale.
NOISE_KEYS = {
    "accel_noise_density": "accelerometer_noise_density",
    "accel_random_walk": "accelerometer_random_walk",
    "gyro_noise_density": "gyroscope_noise_density",
    "gyro_random_walk": "gyroscope_random_walk",
}
TYPICAL = ImuNoise()
PLAUSIBLE_RANGE = (0.01, 1000.0)  # x the typical value: outside it, no real IMU (or the wrong unit)

# Peak memory of a camera-IMU solve, measured with experiments/bench_calibrator.py (real-size cases):
# about 2.5 kB per corner (whitened Jacobians, the batched projection pass, the robust covariance) and
# 25 kB per frame (its state, IMU factor and GTSAM's elimination).
BYTES_PER_CORNER = 2500
BYTES_PER_FRAME = 25_000

# Below this share of the image inside the hull of all corners, the lens model is extrapolated.
MIN_IMAGE_COVERAGE = 0.5
# Where it is extrapolated: a ninth of the image holding under this share of all corners (a few stray
# corners reach a ninth without measuring the distortion there) ...
SPARSE_REGION_SHARE = 0.01
# ... and a band this share of the width (height) wide along a border that holds no corner at all.
EDGE_BAND_SHARE = 0.1
IMAGE_REGIONS = (
    ("top-left corner", "top edge", "top-right corner"),
    ("left edge", "centre", "right edge"),
    ("bottom-left corner", "bottom edge", "bottom-right corner"),
)


def check_imu_noise(noise: ImuNoise) -> list[str]:
    """Refuse noise settings that are zero, negative or not finite; warn about implausible ones.

    Returns:
        Plain-language warnings (the solve still runs: each sensor is weighted by the noise its
        residuals show, ``vical.calib.solve.variance``).

    Raises:
        CalibrationError: naming the imu.yaml key of a value that cannot be a noise density.
    """
    warnings = []
    for field, key in NOISE_KEYS.items():
        value, typical = getattr(noise, field), getattr(TYPICAL, field)
        if not (math.isfinite(value) and value > 0):
            raise CalibrationError(
                f"IMU noise setting {key} must be a positive finite number, got {value}; set it in the imu.yaml "
                f"(a MEMS IMU: about {typical:g})"
            )
        ratio = value / typical
        if not PLAUSIBLE_RANGE[0] <= ratio <= PLAUSIBLE_RANGE[1]:
            warnings.append(
                f"IMU noise setting {key} = {value:g} is {ratio:.3g}x a typical MEMS IMU's ({typical:g}): check its "
                "unit and value in the imu.yaml; the solve weights the IMU by the noise its residuals show anyway"
            )
    return warnings


def estimated_memory_mb(frames: int, corners: int) -> float:
    """Peak extra memory [MB] of a camera-IMU solve of ``frames`` frames with ``corners`` corners in all."""
    return (BYTES_PER_CORNER * corners + BYTES_PER_FRAME * frames) / 1e6


def check_memory(frames: int, corners: int, limit_mb: float, stride: int) -> None:
    """Refuse, before solving, a recording that would need more than ``limit_mb``; name the option that thins it."""
    need = estimated_memory_mb(frames, corners)
    if need <= limit_mb:
        return
    thin = math.ceil(stride * need / limit_mb)
    raise CalibrationSettingError(
        f"the recording's {frames} frames with {corners} corners need about {need:.0f} MB to calibrate, more than the "
        f"limit of {limit_mb:.0f} MB; keep one frame in {thin} ({{fix}}) or raise the limit ({{memory_limit_mb}})",
        "frame_stride", str(thin), str(thin), {"memory_limit_mb": (None, None)},
    )  # fmt: skip


def image_coverage_warnings(observations: Sequence[FrameObservation], size: tuple[int, int]) -> list[str]:
    """A warning when the corners of all views cover less than ``MIN_IMAGE_COVERAGE`` of the image
    (their convex hull), naming where: the ninths of the image with under ``SPARSE_REGION_SHARE`` of the
    corners, and the borders whose outer ``EDGE_BAND_SHARE`` band holds none."""
    points = np.concatenate([o.uv for o in observations]).astype(np.float32) if observations else np.zeros((0, 2))
    width, height = size
    if len(points) < 3:
        return []
    share = cv2.contourArea(cv2.convexHull(points)) / (width * height)
    if share >= MIN_IMAGE_COVERAGE:
        return []
    sparse, borders = sparse_regions(points, size), empty_borders(points, size)
    where = []
    if sparse:
        where.append(f"under {SPARSE_REGION_SHARE:.0%} of the corners in the {', '.join(sparse)}")
    if borders:
        along = "any border" if len(borders) == 4 else f"the {_and_list(borders)} border{'s' * (len(borders) > 1)}"
        where.append(f"no corner in the outer {EDGE_BAND_SHARE:.0%} along {along}")
    located = f" ({'; '.join(where)})" if where else ""
    return [
        f"the board's corners covered only {share:.0%} of the image{located}: the lens distortion there is "
        "extrapolated, not measured; show the board near every edge and corner of the image"
    ]


def sparse_regions(points: np.ndarray, size: tuple[int, int]) -> list[str]:
    """The ninths of the image (``IMAGE_REGIONS``) holding under ``SPARSE_REGION_SHARE`` of the corners (N, 2) [px]."""
    width, height = size
    col = np.clip((points[:, 0] * 3 // width).astype(int), 0, 2)
    row = np.clip((points[:, 1] * 3 // height).astype(int), 0, 2)
    counts = np.zeros((3, 3), dtype=np.int64)
    np.add.at(counts, (row, col), 1)
    limit = SPARSE_REGION_SHARE * len(points)
    return [IMAGE_REGIONS[r][c] for r in range(3) for c in range(3) if counts[r, c] < limit]


def empty_borders(points: np.ndarray, size: tuple[int, int]) -> list[str]:
    """The image borders (``top``, ``bottom``, ``left``, ``right``) with no corner (N, 2) [px] in their band
    ``EDGE_BAND_SHARE`` of the image's height (width) wide."""
    width, height = size
    u, v = points[:, 0], points[:, 1]
    bands = {
        "top": v < EDGE_BAND_SHARE * height,
        "bottom": v >= (1 - EDGE_BAND_SHARE) * height,
        "left": u < EDGE_BAND_SHARE * width,
        "right": u >= (1 - EDGE_BAND_SHARE) * width,
    }
    return [border for border, inside in bands.items() if not inside.any()]


def _and_list(items: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"

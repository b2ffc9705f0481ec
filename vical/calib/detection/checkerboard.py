"""Checkerboard corner detection with ids in Kalibr's numbering.

OpenCV's ``findChessboardCorners`` returns the inner corners row by row, but which corner it
starts from depends on how the board is seen. The ids are fixed here in two steps: first the
labelling must be right-handed in the image (board z towards the camera, see
``docs/conventions.md``), then the printed colours decide between the two remaining
labellings that differ by a half-turn: the square diagonally outside point id 0 is black
(``Target.square_is_black``).
"""

from __future__ import annotations

import cv2
import numpy as np

from vical.calib.errors import CalibrationError
from vical.data.target import Target

FIND_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
# When the first pass finds nothing: its fast check erodes squares of about 10 px away (a board far off,
# or small in a fisheye's image) and rejects the image; this pass skips it. Without the adaptive
# threshold it costs about one more first pass on a frame without a board (with it: 3 to 10 more).
SMALL_SQUARE_FLAGS = cv2.CALIB_CB_NORMALIZE_IMAGE
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)


def detect_checkerboard(image: np.ndarray, target: Target) -> tuple[np.ndarray, np.ndarray]:
    """Find the checkerboard's inner corners in a grey image.

    Args:
        image: (H, W) uint8 grey image.
        target: the checkerboard (``rows x cols`` inner corners).

    Returns:
        corners (K, 2) float64 [px] (centre of the top-left pixel at (0, 0)) and ids (K,) int64
        in Kalibr's numbering; both empty unless the whole board was found.
    """
    _check_inputs(image, target)
    found, raw = cv2.findChessboardCorners(image, (target.cols, target.rows), flags=FIND_FLAGS)
    if not found:
        found, raw = cv2.findChessboardCorners(image, (target.cols, target.rows), flags=SMALL_SQUARE_FLAGS)
    if not found or raw is None or len(raw) != target.num_points:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    grid = raw.reshape(target.rows, target.cols, 2).astype(np.float32)
    window = _subpixel_window(grid)
    refined = cv2.cornerSubPix(image, grid.reshape(-1, 1, 2).copy(), (window, window), (-1, -1), _SUBPIX_CRITERIA)
    grid = refined.reshape(target.rows, target.cols, 2).astype(np.float64)
    labelled = _label_grid(grid, image, target)
    if labelled is None:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    return labelled.reshape(-1, 2), np.arange(target.num_points, dtype=np.int64)


def _check_inputs(image: np.ndarray, target: Target) -> None:
    if target.kind != "checkerboard":
        raise CalibrationError(f"detect_checkerboard needs a checkerboard target, got {target.kind!r}")
    if not isinstance(image, np.ndarray) or image.ndim != 2 or image.dtype != np.uint8:
        shape = getattr(image, "shape", None)
        dtype = getattr(image, "dtype", type(image).__name__)
        raise CalibrationError(
            f"detect_checkerboard needs an (H, W) uint8 grey image, got shape {shape} dtype {dtype}; "
            "convert colour images with cv2.cvtColor(..., cv2.COLOR_BGR2GRAY)"
        )


def _subpixel_window(grid: np.ndarray) -> int:
    """Half-size [px] of the cornerSubPix search window: at most 5 px, under half a square."""
    steps = np.concatenate(
        [np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel(), np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel()]
    )
    return int(np.clip(np.floor(0.4 * np.min(steps)), 2, 5))


def _candidate_labellings(grid: np.ndarray) -> list[np.ndarray]:
    """Every relabelling of the (rows, cols, 2) grid that keeps its shape (flips; transposes if square)."""
    flips = [grid, grid[::-1], grid[:, ::-1], grid[::-1, ::-1]]
    if grid.shape[0] == grid.shape[1]:
        flips += [g.transpose(1, 0, 2) for g in flips]
    return flips


def _is_right_handed(grid: np.ndarray) -> bool:
    """True when board z points towards the camera: (d row) x (d col) < 0 in (u, v) pixels."""
    d_row = grid[-1, 0] - grid[0, 0]
    d_col = grid[0, -1] - grid[0, 0]
    return bool(d_row[0] * d_col[1] - d_row[1] * d_col[0] < 0)


def _colour_score(grid: np.ndarray, image: np.ndarray, target: Target) -> float:
    """Mean grey of squares that should be white minus that of squares that should be black."""
    board_xy = target.points[:, :2].astype(np.float32)
    H, _ = cv2.findHomography(board_xy, grid.reshape(-1, 2).astype(np.float32))
    if H is None:
        return -np.inf
    i, j = np.meshgrid(np.arange(target.rows + 1), np.arange(target.cols + 1), indexing="ij")
    centres = np.stack([(i - 0.5) * target.row_spacing, (j - 0.5) * target.col_spacing], axis=-1).reshape(-1, 2)
    uv = cv2.perspectiveTransform(centres.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)
    cols, rows = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
    inside = (cols >= 0) & (cols < image.shape[1]) & (rows >= 0) & (rows < image.shape[0])
    black = target.square_is_black(i, j).ravel()
    if not np.any(inside & black) or not np.any(inside & ~black):
        return -np.inf
    grey = np.zeros(len(uv))
    grey[inside] = image[rows[inside], cols[inside]]
    return float(np.mean(grey[inside & ~black]) - np.mean(grey[inside & black]))


def _label_grid(grid: np.ndarray, image: np.ndarray, target: Target) -> np.ndarray | None:
    """The (rows, cols, 2) grid relabelled in Kalibr's numbering, or None if no labelling fits the colours."""
    candidates = [g for g in _candidate_labellings(grid) if _is_right_handed(g)]
    scores = [_colour_score(g, image, target) for g in candidates]
    best = int(np.argmax(scores))
    if not scores[best] > 0:
        return None
    return np.ascontiguousarray(candidates[best])

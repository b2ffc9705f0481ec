"""Whether the lens model fits the lens: residuals that depend on where in the image a corner lies.

A model that describes the lens leaves residuals that are the detector's noise. One that cannot
(a pinhole-radtan model on a fisheye lens) leaves errors that vary smoothly over the image and are
the same at the same image position in every view. Two measures follow:

- the corner noise, from the residuals of neighbouring corners (nearest on the board, same view):
  they share a smooth error but not their noise, so ``sigma_noise^2 = mean |r_i - r_j|^2 / 4`` per
  image axis, whatever the model;
- the residual field: the mean residual of the corners in each cell of a ``GRID`` over the image,
  minus what their noise alone gives it (``|mean|^2 - (var_u + var_v) / n``), RMS over the cells
  weighted by their corners. Unmodelled motion effects (a rolling shutter) give errors that change
  with each view's motion and average out here, a lens model's error does not.

Measured (30 views, 0.3 px noise; 8 s and 20 s recordings for the rolling shutter): a field of
0.22-0.83 px per axis for radtan or equidistant on 120-180 deg fisheyes against 0.42-1.3 px of
neighbour noise; 0.00 for the right models; at most 0.034 px with a 5-30 ms rolling shutter.
"""

from __future__ import annotations

import numpy as np

from vical.geometry import CAMERA_MODELS, CameraModel

GRID = (8, 6)  # cells across and down the image
MIN_CELL_CORNERS = 10
MIN_PAIRS = 50  # neighbour pairs needed for a noise estimate
FIELD_NOISE_RATIO = 0.25  # a field beyond a quarter of the corner noise is a model error ...
MIN_FIELD_PX = 0.15  # [px] ... and one below this hardly matters for the calibration
MISFIT = "model does not fit this lens"  # in every warning this module gives about a calibrated model
MISFIT_FAIL_PX = 0.5  # [px per axis] a residual field this large is no detector's noise: the calibration fails


def neighbour_noise(points: list[np.ndarray], residuals: list[np.ndarray]) -> float | None:
    """Corner noise [px] per image axis from the residual differences of neighbouring corners, or None
    when fewer than ``MIN_PAIRS`` pairs exist.

    Args:
        points: each frame's board points (K_i, 3) [m]; residuals: (K_i, 2) [px] per frame, in the same order.
    """
    differences = []
    for board, res in zip(points, residuals, strict=True):
        if len(board) < 2:
            continue
        distance = np.linalg.norm(board[:, None, :] - board[None, :, :], axis=2)
        np.fill_diagonal(distance, np.inf)
        differences.append(res - res[np.argmin(distance, axis=1)])
    if not differences or sum(len(d) for d in differences) < MIN_PAIRS:
        return None
    d = np.concatenate(differences)
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1)) / 4.0))


def residual_field(camera: CameraModel, uv: np.ndarray, residuals: np.ndarray) -> float | None:
    """RMS [px per axis] of the mean residual by image cell beyond the corner noise, or None when no cell
    has ``MIN_CELL_CORNERS`` corners.

    Args:
        camera: the camera (its image size); uv: (N, 2) [px] measured corners; residuals: (N, 2) [px].
    """
    cols = np.clip((uv[:, 0] / camera.width * GRID[0]).astype(int), 0, GRID[0] - 1)
    rows = np.clip((uv[:, 1] / camera.height * GRID[1]).astype(int), 0, GRID[1] - 1)
    cell = rows * GRID[0] + cols
    weighted, corners = 0.0, 0
    for c in np.unique(cell):
        r = residuals[cell == c]
        if len(r) < MIN_CELL_CORNERS:
            continue
        mean = r.mean(axis=0)
        weighted += len(r) * (mean @ mean - r.var(axis=0, ddof=1).sum() / len(r))
        corners += len(r)
    return None if corners == 0 else float(np.sqrt(max(weighted / corners, 0.0) / 2.0))


def lens_misfit(
    camera: CameraModel, points: np.ndarray, uv: np.ndarray, residuals: np.ndarray, frame_of: np.ndarray
) -> tuple[float, float] | None:
    """(residual field, corner noise) [px per axis] of a solve's corners, or None where either cannot be measured.

    Args:
        camera: the camera; points: (N, 3) [m] the corners' board points; uv: (N, 2) [px] as measured;
        residuals: (N, 2) [px]; frame_of: (N,) each corner's frame (any labels, the corners of a frame together
            or not).
    """
    frames = [np.flatnonzero(frame_of == f) for f in np.unique(frame_of)]
    noise = neighbour_noise([points[k] for k in frames], [residuals[k] for k in frames])
    field = residual_field(camera, uv, residuals)
    return None if noise is None or field is None else (field, noise)


def misfit_warnings(camera: CameraModel, misfit: tuple[float, float] | None) -> list[str]:
    """A warning when the residuals depend on the image position (the model does not fit the lens), else none.

    Args:
        camera: the calibrated camera; misfit: its corners' (residual field, corner noise) (``lens_misfit``).
    """
    if misfit is None or not is_misfit(*misfit):
        return []
    field, noise = misfit
    others = ", ".join(m for m in CAMERA_MODELS if m != camera.distortion)
    return [
        f"the {camera.distortion} {MISFIT}: its residuals depend on where a corner lies in the image "
        f"(a systematic {field:.2f} px per axis, the same in every view, beside {noise:.2f} px of corner noise "
        f"between neighbouring corners); try another lens model ({others})"
    ]


def is_misfit(field: float, noise: float) -> bool:
    """Whether a residual field [px per axis] beside the corner noise [px] says the model does not fit the lens."""
    return field > max(FIELD_NOISE_RATIO * noise, MIN_FIELD_PX)


def given_intrinsics_warnings(camera: CameraModel, misfit: tuple[float, float] | None) -> list[str]:
    """A warning when known intrinsics (the extrinsic task's ``--intrinsics``) leave a residual field."""
    if misfit is None or not is_misfit(*misfit):
        return []
    field, noise = misfit
    return [
        f"the given {camera.distortion} intrinsics do not fit these corners: the residuals depend on where a corner "
        f"lies in the image (a systematic {field:.2f} px per axis, the same in every view, beside {noise:.2f} px of "
        "corner noise between neighbouring corners); calibrate the intrinsics on these corners (--task joint) or "
        "check the --intrinsics file and its lens model"
    ]


def is_model_warning(warning: str) -> bool:
    """Whether ``warning`` is this module's (or the model comparison that follows it)."""
    return MISFIT in warning or warning.startswith(COMPARISON)


COMPARISON = "lens models on these corners"

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
import scipy.spatial

from vical.geometry import CAMERA_MODELS, CameraModel

GRID = (8, 6)  # cells across and down the image
MIN_CELL_CORNERS = 10
MIN_PAIRS = 50  # neighbour pairs needed for a noise estimate
FIELD_NOISE_RATIO = 0.25  # a field beyond a quarter of the corner noise is a model error ...
MIN_FIELD_PX = 0.15  # [px] ... and one below this hardly matters for the calibration
MISFIT = "model does not fit this lens"  # in every warning this module gives about a calibrated model
MISFIT_FAIL_PX = 0.5  # [px per axis] a residual field this large is no detector's noise: the calibration fails


def neighbour_noise(points: np.ndarray, residuals: np.ndarray, frame_of: np.ndarray) -> float | None:
    """Corner noise [px] per image axis from the residual differences of neighbouring corners, or None
    when fewer than ``MIN_PAIRS`` pairs exist.

    Each corner is paired with its nearest corner on the board in the same view (one k-d tree over all
    views, each lifted apart from the others along a fourth axis; among equally near corners the tree picks
    one). Corners alone in their view have no pair.

    Args:
        points: (N, 3) [m] the corners' board points; residuals: (N, 2) [px]; frame_of: (N,) each corner's view.
    """
    if len(points) < 2:
        return None
    _, view = np.unique(frame_of, return_inverse=True)
    apart = 10.0 * (float(np.ptp(points, axis=0).max()) + 1.0)  # [m] further than any two corners of one view
    lifted = np.column_stack([points, view * apart])
    distance, nearest = scipy.spatial.cKDTree(lifted, balanced_tree=False, compact_nodes=False).query(lifted, k=2)
    paired = distance[:, 1] < apart / 10.0
    if paired.sum() < MIN_PAIRS:
        return None
    d = residuals[paired] - residuals[nearest[paired, 1]]
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
    noise = neighbour_noise(points, residuals, frame_of)
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

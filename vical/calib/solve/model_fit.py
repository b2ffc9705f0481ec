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

from vical.calib.solve.observations import FrameObservation
from vical.geometry import CAMERA_MODELS, CameraModel

GRID = (8, 6)  # cells across and down the image
MIN_CELL_CORNERS = 10
MIN_PAIRS = 50  # neighbour pairs needed for a noise estimate
FIELD_NOISE_RATIO = 0.25  # a field beyond a quarter of the corner noise is a model error ...
MIN_FIELD_PX = 0.15  # [px] ... and one below this hardly matters for the calibration
MISFIT = "model does not fit this lens"  # in every warning this module gives


def neighbour_noise(observations: list[FrameObservation], residuals: list[np.ndarray]) -> float | None:
    """Corner noise [px] per image axis from the residual differences of neighbouring corners, or None
    when fewer than ``MIN_PAIRS`` pairs exist.

    Args:
        observations: the frames' corners; residuals: (K_i, 2) [px] per frame, in the corners' order.
    """
    differences = []
    for obs, res in zip(observations, residuals, strict=True):
        if len(obs.ids) < 2:
            continue
        distance = np.linalg.norm(obs.points[:, None, :] - obs.points[None, :, :], axis=2)
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


def misfit_warnings(
    camera: CameraModel, observations: list[FrameObservation], residuals: list[np.ndarray]
) -> list[str]:
    """A warning when the residuals depend on the image position (the model does not fit the lens), else none.

    Args:
        camera: the calibrated camera; observations and residuals (measured minus predicted, (K_i, 2)
            [px]) per frame.
    """
    noise = neighbour_noise(observations, residuals)
    field = residual_field(camera, np.concatenate([o.uv for o in observations]), np.concatenate(residuals))
    if noise is None or field is None or field <= max(FIELD_NOISE_RATIO * noise, MIN_FIELD_PX):
        return []
    others = ", ".join(m for m in CAMERA_MODELS if m != camera.distortion)
    return [
        f"the {camera.distortion} {MISFIT}: its residuals depend on where a corner lies in the image "
        f"(a systematic {field:.2f} px per axis, the same in every view, beside {noise:.2f} px of corner noise "
        f"between neighbouring corners); try another lens model ({others})"
    ]


def is_model_warning(warning: str) -> bool:
    """Whether ``warning`` is this module's (or the model comparison that follows it)."""
    return MISFIT in warning or warning.startswith(COMPARISON)


COMPARISON = "lens models on these corners"

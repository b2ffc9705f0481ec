"""Whether the lens model fits the lens: residuals that are systematic rather than corner noise.

A model that describes the lens leaves residuals that are the detector's noise, independent from
corner to corner. One that cannot (a pinhole-radtan model on a fisheye lens) leaves errors that
vary smoothly over the image, so neighbouring corners of a view share them. The difference of
the residuals of neighbouring corners (nearest on the board, in the same view) therefore measures
the corner noise alone, whatever the model: ``sigma_noise^2 = mean |r_i - r_j|^2 / 4`` per image axis.
What the residuals hold beyond it, ``sqrt(rms^2 - sigma_noise^2)``, is systematic.
"""

from __future__ import annotations

import numpy as np

from vical.calib.observations import FrameObservation
from vical.geometry import CAMERA_MODELS, CameraModel

MIN_PAIRS = 50  # neighbour pairs needed for a noise estimate
SYSTEMATIC_NOISE_RATIO = 0.5  # the right model measured 0 (least squares leaves the rms below the noise) ...
MIN_SYSTEMATIC_PX = 0.2  # [px] ... and below this it hardly matters for the calibration


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


def misfit_warnings(
    camera: CameraModel, observations: list[FrameObservation], residuals: list[np.ndarray]
) -> list[str]:
    """A warning when the residuals are mostly systematic (the model does not fit the lens), else none.

    Args:
        camera: the calibrated camera; observations and residuals (measured minus predicted, (K_i, 2)
            [px]) per frame.
    """
    noise = neighbour_noise(observations, residuals)
    if noise is None:
        return []
    all_residuals = np.concatenate(residuals)
    rms = float(np.sqrt(np.mean(all_residuals**2)))  # per image axis
    systematic = float(np.sqrt(max(rms**2 - noise**2, 0.0)))
    if systematic <= max(SYSTEMATIC_NOISE_RATIO * noise, MIN_SYSTEMATIC_PX):
        return []
    others = ", ".join(m for m in CAMERA_MODELS if m != camera.distortion)
    return [
        f"the {camera.distortion} model does not fit this lens: its residuals ({rms:.2f} px rms per axis) hold "
        f"{systematic:.2f} px of systematic error beyond the {noise:.2f} px of corner noise that neighbouring corners "
        f"show; try another lens model ({others}), unless the images are distorted otherwise (rolling shutter)"
    ]

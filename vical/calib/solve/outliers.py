"""Outliers: corners far from where the fitted target pose puts them, and frames that fit no pose.

Real detectors return a few bad corners (a reflection mistaken for a junction, a tag decoded on
the wrong board), corner noise with heavier tails than a Gaussian's and, rarely, frames whose ids
are scrambled. Least squares lets each of them pull the whole solution, so they are removed
before the final solve, and the result says how many, by which threshold and in which frames:

- the corner noise is estimated robustly from the median residual norm (for 2-D Gaussian noise of
  sigma per axis the norm is Rayleigh distributed with median ``sigma sqrt(2 ln 2)``);
- a corner whose residual exceeds ``OUTLIER_SIGMAS`` of that sigma (and ``MIN_OUTLIER_PX``) is
  an outlier;
- a frame that loses more than ``MAX_OUTLIER_FRACTION`` of its corners is dropped whole: its
  detection as such is not trustworthy.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from vical.calib.solve.initialization import pnp, undistorted
from vical.calib.solve.observations import FrameObservation
from vical.geometry import CameraModel

OUTLIER_SIGMAS = 5.0  # a Gaussian corner exceeds 5 sigma per axis about once in 3e5 corners
MIN_OUTLIER_PX = 1.0  # [px] never call a corner an outlier below this (noise-free data has sigma ~ 0)
MAX_OUTLIER_FRACTION = 0.25  # a frame losing more of its corners than this is dropped whole
_RAYLEIGH_MEDIAN = float(np.sqrt(2.0 * np.log(2.0)))


def robust_sigma_of_norms(norms: np.ndarray) -> float:
    """Per-axis corner noise [px] from residual norms (N,) [px], insensitive to a minority of outliers."""
    return float(np.median(norms) / _RAYLEIGH_MEDIAN) if len(norms) else 0.0


def keep_inliers(obs: FrameObservation, inliers: np.ndarray) -> FrameObservation:
    """The observation restricted to the corners where the mask ``inliers`` (K,) is True."""
    return replace(obs, uv=obs.uv[inliers], ids=obs.ids[inliers], points=obs.points[inliers])


def robust_pose(
    camera: CameraModel, obs: FrameObservation, threshold: float, min_corners: int
) -> tuple[np.ndarray, np.ndarray] | None:
    """PnP pose ``T_cam_target`` (4, 4) and inlier mask (K,), removing the worst corner until all fit.

    Each round refits without the corner of largest residual, so one far-off corner cannot drag
    the pose and make its neighbours look wrong. Returns None when the frame is an outlier (fewer
    than ``min_corners`` left, or more than ``MAX_OUTLIER_FRACTION`` of its corners removed) or PnP fails.
    """
    inliers = np.ones(len(obs.ids), dtype=bool)
    max_removed = int(np.floor(MAX_OUTLIER_FRACTION * len(obs.ids)))
    xy = undistorted(camera, obs.uv)  # once: each round refits on a subset of the same rays
    for _ in range(max_removed + 1):
        if inliers.sum() < min_corners:
            return None
        subset = keep_inliers(obs, inliers)
        fit = pnp(camera, subset, xy[inliers])
        if fit is None:
            return None
        T = fit[0]
        norms = np.linalg.norm(subset.residuals(camera, T), axis=1)
        if norms.max() <= threshold:
            return T, inliers
        inliers[np.flatnonzero(inliers)[int(np.argmax(norms))]] = False
    return None


def rejection_warnings(
    observations: list[FrameObservation], dropped: list[int], corners: dict[int, int], threshold: float, sigma: float
) -> list[str]:
    """Plain-language notes on outlier corners (how many, by which rule, in which frames) and dropped frames.

    ``dropped`` and the keys of ``corners`` are frame indices; frames are named by ``FrameObservation.label``.
    """
    labels = {o.index: o.label for o in observations}
    notes = []
    if corners:
        rejected, total = sum(corners.values()), sum(len(o.ids) for o in observations)
        rule = (
            f"{OUTLIER_SIGMAS:g} x the corner noise measured robustly from all residuals ({sigma:.3g} px)"
            if threshold > MIN_OUTLIER_PX
            else f"the {MIN_OUTLIER_PX:g} px floor (the measured corner noise is only {sigma:.3g} px)"
        )
        notes.append(
            f"{rejected} of {total} corners ({100 * rejected / total:.2g} %) in {len(corners)} frames are outliers and "
            f"were left out: their reprojection error after fitting the frame's pose exceeds {threshold:.2f} px, "
            f"{rule}; frames {_listing([labels[k] for k in sorted(corners)])}"
        )
    if dropped:
        notes.append(
            f"{len(dropped)} of {len(observations)} frames with detections fit no target pose even without their "
            f"worst {MAX_OUTLIER_FRACTION:.0%} of corners (scrambled ids, or another target than the one given?) and "
            f"were dropped: frames {_listing([labels[k] for k in dropped])}"
        )
    return notes


def _listing(labels: list[str], limit: int = 12) -> str:
    shown = ", ".join(labels[:limit])
    return shown + (f", ... ({len(labels) - limit} more)" if len(labels) > limit else "")


@dataclass(frozen=True)
class Rejection:
    """Observations and poses after removing wrong detections.

    Attributes:
        observations: the input list with outlier corners removed (same length and order).
        poses: ``{observation index: T_cam_target (4, 4)}`` of the frames kept.
        warnings: plain-language notes on what was removed (empty when nothing was).
        threshold: [px] the residual norm above which corners were rejected.
        dropped: frame indices (``FrameObservation.index``) of the frames dropped whole.
    """

    observations: list[FrameObservation]
    poses: dict[int, np.ndarray]
    warnings: list[str]
    threshold: float
    dropped: list[int] = field(default_factory=list)

    @property
    def changed(self) -> bool:
        return bool(self.warnings)


def reject_outliers(
    camera: CameraModel, observations: list[FrameObservation], poses: dict[int, np.ndarray], min_corners: int
) -> Rejection:
    """Remove corners and frames that the fitted poses do not explain.

    Args:
        camera: the (calibrated or known) camera.
        observations: every frame's observation.
        poses: ``{observation index: T_cam_target (4, 4)}`` fitted so far (PnP or a solve); the
            residual threshold comes from these frames. Frames with at least ``min_corners``
            corners but no pose are tried again (a far-off corner can make plain PnP fail).
        min_corners: fewest corners a frame must keep.
    """
    if not poses:
        return Rejection(list(observations), {}, [], MIN_OUTLIER_PX)
    norms = {k: np.linalg.norm(observations[k].residuals(camera, T), axis=1) for k, T in poses.items()}
    sigma = robust_sigma_of_norms(np.concatenate(list(norms.values())))
    threshold = max(OUTLIER_SIGMAS * sigma, MIN_OUTLIER_PX)
    cleaned, kept, dropped, rejected = list(observations), {}, [], {}
    for k, obs in enumerate(observations):
        if k in norms and norms[k].max() <= threshold:
            kept[k] = poses[k]
            continue
        if k not in norms and len(obs.ids) < min_corners:
            continue
        fit = robust_pose(camera, obs, threshold, min_corners)
        if fit is None:
            dropped.append(obs.index)
            continue
        kept[k], inliers = fit
        if not inliers.all():
            cleaned[k] = keep_inliers(obs, inliers)
            rejected[obs.index] = int((~inliers).sum())
    notes = rejection_warnings(observations, dropped, rejected, threshold, sigma)
    return Rejection(cleaned, kept, notes, threshold, dropped)

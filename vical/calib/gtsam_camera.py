"""Bridge between ``vical.geometry.CameraModel`` and GTSAM's calibration classes and factors.

``radtan`` maps to ``Cal3DS2`` and ``equidistant`` to ``Cal3Fisheye``; both are 9-dimensional
``[fx, fy, s, u0, v0, d1, d2, d3, d4]`` with additive tangent spaces. The skew ``s`` is pinned
to zero by a prior (Kalibr's pinhole has no skew).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import gtsam_unstable
import numpy as np

from vical.calib.errors import CalibrationError
from vical.geometry import CameraModel

SKEW_SIGMA = 1e-4  # [px] prior pinning the skew to zero; tighter made LM much slower
FREE_SIGMA = 1e6  # [px or unit-less] prior sigma that leaves a calibration parameter unconstrained
CALIBRATION_DIM = 9
# Order of CameraModel parameters inside GTSAM's 9-vector: fx, fy, (skew), cx, cy, d1..d4.
MODEL_INDEX = np.array([0, 1, 3, 4, 5, 6, 7, 8])


@dataclass(frozen=True)
class GtsamCameraKind:
    """The GTSAM classes of one distortion model."""

    calibration: type
    prior: type
    sfm_factor: type  # GeneralSFMFactor2 (pose, landmark, calibration)
    ppp_factor: type  # ProjectionFactorPPP (pose, transform, landmark; fixed calibration)
    pppc_factor: type  # ProjectionFactorPPPC (pose, transform, landmark, calibration)


KINDS = {
    "radtan": GtsamCameraKind(
        gtsam.Cal3DS2,
        gtsam.PriorFactorCal3DS2,
        gtsam.GeneralSFMFactor2Cal3DS2,
        gtsam_unstable.ProjectionFactorPPPCal3DS2,
        gtsam_unstable.ProjectionFactorPPPCCal3DS2,
    ),
    "equidistant": GtsamCameraKind(
        gtsam.Cal3Fisheye,
        gtsam.PriorFactorCal3Fisheye,
        gtsam.GeneralSFMFactor2Cal3Fisheye,
        gtsam_unstable.ProjectionFactorPPPCal3Fisheye,
        gtsam_unstable.ProjectionFactorPPPCCal3Fisheye,
    ),
}


def kind_of(model: str) -> GtsamCameraKind:
    """GTSAM classes of the distortion model ``"radtan"`` or ``"equidistant"``."""
    if model not in KINDS:
        raise CalibrationError(f"camera model {model!r} is not supported; use one of {sorted(KINDS)}")
    return KINDS[model]


def to_gtsam(camera: CameraModel):
    """``Cal3DS2`` / ``Cal3Fisheye`` of a camera (zero skew)."""
    if np.any(camera.distortion_center_offset != 0):
        raise CalibrationError("the calibrator's camera models have the distortion centre at the principal point")
    return kind_of(camera.distortion).calibration(camera.fx, camera.fy, 0.0, camera.cx, camera.cy, *camera.dist)


def calibration_vector(calibration) -> np.ndarray:
    """(9,) ``[fx, fy, s, u0, v0, d1, d2, d3, d4]`` of a GTSAM calibration."""
    if isinstance(calibration, gtsam.Cal3Fisheye):
        c = calibration
        return np.array([c.fx(), c.fy(), c.skew(), c.px(), c.py(), c.k1(), c.k2(), c.k3(), c.k4()])
    return np.asarray(calibration.vector(), dtype=float)


def from_gtsam(calibration, like: CameraModel) -> CameraModel:
    """The ``CameraModel`` of a GTSAM calibration, with the image size and model of ``like``."""
    v = calibration_vector(calibration)
    return like.with_intrinsics(v[0], v[1], v[3], v[4], v[5:9])


def skew_prior(key: int, calibration):
    """Prior that pins the skew of the calibration at ``key`` to zero and leaves the rest free."""
    sigmas = np.full(CALIBRATION_DIM, FREE_SIGMA)
    sigmas[2] = SKEW_SIGMA
    kind = KINDS["equidistant" if isinstance(calibration, gtsam.Cal3Fisheye) else "radtan"]
    return kind.prior(key, calibration, gtsam.noiseModel.Diagonal.Sigmas(sigmas))


def pixel_noise(sigma_px: float, huber_k: float | None):
    """Isotropic 2-D pixel noise [px], optionally wrapped in a Huber kernel of width ``huber_k`` sigmas."""
    base = gtsam.noiseModel.Isotropic.Sigma(2, sigma_px)
    if huber_k is None:
        return base
    return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k), base)

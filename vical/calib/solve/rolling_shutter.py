"""Rolling shutters: what a global-shutter solve's residuals say about one, and a line delay the data do not tell.

A rolling shutter exposes image row ``v`` at ``t + line_delay * v``. While the image moves at ``g_i`` [px/s] at
corner ``i``, the corner lands ``g_i * readout * v_i / H`` from where a global shutter at the frame's time puts it
(``readout = line_delay * H``). A global-shutter solve absorbs the part common to every row into its time offset
and leaves the rest in the residuals ``r_i``, so the readout that explains them is the coefficient ``R`` of

    r_i = R * (v_i / H) g_i + b * g_i + noise

(least squares over all corners; ``b`` takes what the time offset did not). Its standard error is cluster-robust
by frame: the corners of one view share its pose error. A ``z = R / sigma_R`` of ``EVIDENCE_Z`` and more, for a
readout that moves the corners by ``MIN_EVIDENT_SHIFT`` of their noise, is evidence of a rolling shutter; global-
shutter data give a standard normal ``z`` (measured in ``docs/calibration.md``, "Rolling shutter").

A line delay estimated from too little image motion stays at its prior: ``unobserved`` names the cameras whose
readout's 1-sigma is above ``READOUT_UNOBSERVED`` of the prior's (the data then tell less than a quarter of the
range readouts have), and the solve keeps their given line delays (``vical.calib.solve.visual_inertial``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vical.calib.solve.corner_factors import CornerFactors
from vical.calib.solve.uncertainty import LINE_DELAY_HINT
from vical.calib.solve.vi_problem import LINE_DELAY_NAME, READOUT_PRIOR_SIGMA

EVIDENCE_Z = 5.0  # z of the residuals' readout above which a global-shutter solve warns ...
MIN_EVIDENT_SHIFT = 0.1  # ... if that readout moves the corners by this fraction of their noise (RMS) or more
READOUT_UNOBSERVED = 0.25  # a readout 1-sigma above this fraction of its prior's: the data hardly tell it


@dataclass(frozen=True)
class ReadoutEvidence:
    """The readout a global-shutter solve's residuals show (``readout_in_residuals``).

    Attributes:
        readout: [s] the readout (line delay times image height) that explains the residuals best.
        sigma: [s] its 1-sigma (cluster-robust by frame).
        shift: [px] the RMS corner shift that readout gives (per image axis).
    """

    readout: float
    sigma: float
    shift: float

    @property
    def z(self) -> float:
        return self.readout / self.sigma if self.sigma > 0 else 0.0

    def evident(self, pixel_sigma: float) -> bool:
        return self.z >= EVIDENCE_Z and self.shift >= MIN_EVIDENT_SHIFT * pixel_sigma


def readout_in_residuals(corners: CornerFactors, values) -> ReadoutEvidence | None:
    """The readout the corner residuals of a global-shutter solve at ``values`` show, or None without the motion at
    the states (a held time offset: no image rates) or with too few frames."""
    rates = corners.image_rates(values)
    if rates is None or len(np.unique(corners.frame_of)) < 3:
        return None
    residuals = corners.residuals(values)  # measured - predicted
    rows = corners.measured[:, 1] / corners.camera.height
    X = np.stack([rates * rows[:, None], rates], axis=2)  # (N, 2 image axes, 2 regressors)
    normal = np.einsum("nai,naj->ij", X, X)
    if np.linalg.cond(normal) > 1e12:
        return None  # no image motion, or no spread in the rows
    inverse = np.linalg.inv(normal)
    coefficients = inverse @ np.einsum("nai,na->i", X, residuals)
    scores = np.zeros((corners.frame_of.max() + 1, 2))
    np.add.at(scores, corners.frame_of, np.einsum("nai,na->ni", X, residuals - X @ coefficients))
    covariance = inverse @ (scores.T @ scores) @ inverse
    readout = float(coefficients[0])
    shift = float(abs(readout) * np.sqrt(np.mean(np.sum((rates * rows[:, None]) ** 2, axis=1)) / 2))
    return ReadoutEvidence(readout, float(np.sqrt(covariance[0, 0])), shift)


def evidence_warning(evidence: ReadoutEvidence | None, pixel_sigma: float) -> list[str]:
    """A note when a global-shutter solve's residuals show a rolling shutter (``ReadoutEvidence.evident``)."""
    if evidence is None or not evidence.evident(pixel_sigma):
        return []
    return [
        f"the corner residuals grow with the image row in proportion to the image's motion, as a rolling "
        f"shutter's do: they alone hold a readout of {evidence.readout * 1e3:.2f} ms (+- {evidence.sigma * 1e3:.2f} "
        f"ms, z = {evidence.z:.0f}; the global-shutter solve absorbed part of the true one), moving the corners by "
        f"{evidence.shift:.2f} px RMS; calibrate with --rolling-shutter (ViOptions(rolling_shutter=True)) to "
        "estimate the line delay"
    ]


def unobserved(results: dict[str, object], heights: dict[str, int]) -> dict[str, float]:
    """The cameras (by name) whose estimated readout's 1-sigma [s] says the data hardly tell it."""
    out = {}
    for name, result in results.items():
        if LINE_DELAY_NAME in result.parameter_names:
            sigma = result.sigma(LINE_DELAY_NAME) * heights[name]
            if not np.isfinite(sigma) or sigma > READOUT_UNOBSERVED * READOUT_PRIOR_SIGMA:
                out[name] = sigma
    return out


def unobserved_warning(sigmas: dict[str, float], given: dict[str, float]) -> str:
    """The note when line delays were left at their priors (``unobserved``): which, how poorly told, what to do."""
    cameras = ", ".join(
        f"{name} (1-sigma {sigma * 1e3:.1f} ms of readout; kept at {given[name] * 1e6:.2f} us/row)"
        for name, sigma in sigmas.items()
    )
    return (
        f"the line delay could not be told from this recording's motion for {cameras}, against a prior of "
        f"{READOUT_PRIOR_SIGMA * 1e3:.0f} ms: every camera's line delay was kept at its given value (the camchain's "
        f"line_delay_nanoseconds, else 0: a global shutter); {LINE_DELAY_HINT}"
    )


__all__ = ["ReadoutEvidence", "evidence_warning", "readout_in_residuals", "unobserved", "unobserved_warning"]

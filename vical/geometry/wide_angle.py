"""Wide-angle projections: double sphere (``ds``), extended unified (``eucm``) and unified (``omni``) camera models.

Each maps a camera-frame point ``p = (x, y, z)`` (N, 3) [m] to pixels as a pinhole on a warped depth::

    u = fx * x / den(p) + cx,    v = fy * y / den(p) + cy

with ``den`` a weighted sum of a distance and the depth, which keeps the projection defined for
rays up to and beyond 90 deg from the optical axis (fields of view of 180 deg and more).

- ``ds`` (Usenko, Demmel, Cremers 2018, "The Double Sphere Camera Model"), coefficients
  ``[xi, alpha]``: ``d1 = |p|``, ``s = xi d1 + z``, ``d2 = sqrt(x^2 + y^2 + s^2)``,
  ``den = alpha d2 + (1 - alpha) s``; ``xi`` in [-1, 1], ``alpha`` in [0, 1].
- ``eucm`` (Khomutenko, Garcia, Martinet 2016, "An Enhanced Unified Camera Model"), coefficients
  ``[alpha, beta]``: ``rho = sqrt(beta (x^2 + y^2) + z^2)``, ``den = alpha rho + (1 - alpha) z``;
  ``alpha`` in [0, 1], ``beta > 0``.
- ``omni`` (Geyer, Daniilidis 2000; Mei, Rives 2007, the unified projection), coefficient ``[xi]``:
  ``den = z + xi |p|``; ``xi >= 0`` (``xi = 0`` is a pinhole, ``xi = 1`` the stereographic projection).

These are the parameterisations of Kalibr's ``ds`` / ``eucm`` / ``omni`` and basalt. Kalibr's ``omni-radtan``
applies the radial-tangential distortion to the omni projection's ``x / den, y / den`` before the focal
lengths (``DISTORTED``; ``vical.geometry.camera`` applies it). Each model projects only part of the space
one-to-one (``valid``): beyond a cone around ``-z`` its image folds back over the image of nearer rays
(``alpha > 0.5``, ``xi > 1``) or its denominator vanishes (``alpha <= 0.5``, ``xi <= 1``). Unprojection is
closed-form and defined on the image of that domain (``unproject``).
"""

from __future__ import annotations

import numpy as np

COEFFICIENTS = {"ds": ("xi", "alpha"), "eucm": ("alpha", "beta"), "omni": ("xi",)}  # of each projection
PROJECTIONS = tuple(COEFFICIENTS)
# Models that distort a projection's x / den, y / den with a pinhole model's distortion (Kalibr's omni-radtan):
# model -> (projection, distortion); its coefficients are the projection's, then the distortion's.
DISTORTED = {"omni-radtan": ("omni", "radtan")}
WIDE_ANGLE_MODELS = (*PROJECTIONS, *DISTORTED)
# Each coefficient's (lowest, highest or None: no bound, whether the lowest is excluded).
_RANGES = {
    "ds": {"xi": (-1.0, 1.0, False), "alpha": (0.0, 1.0, False)},
    "eucm": {"alpha": (0.0, 1.0, False), "beta": (0.0, None, True)},
    "omni": {"xi": (0.0, None, False)},
}


def check_coefficients(model: str, coeffs: np.ndarray) -> str | None:
    """Why ``coeffs`` cannot describe a ``model`` lens (one line naming the parameter), or None when they can."""
    invalid = invalid_coefficient(model, coeffs)
    if invalid is None:
        return None
    name, allowed = invalid
    return f"{model} parameter {name} must be {allowed}, got {coeffs[COEFFICIENTS[model].index(name)]}"


def invalid_coefficient(model: str, coeffs: np.ndarray) -> tuple[str, str] | None:
    """The first of ``coeffs`` (a projection's, ``COEFFICIENTS[model]``) outside its valid range, as (its name,
    the range in words), or None when none is.

    The one place of the ranges: the camera model and the simulator's sensor config both check against it.
    """
    for name, value in zip(COEFFICIENTS[model], coeffs, strict=True):
        low, high, low_open = _RANGES[model][name]
        if high is None:
            valid_value, allowed = (value > low, f"> {low:g}") if low_open else (value >= low, f">= {low:g}")
        else:
            valid_value, allowed = low <= value <= high, f"in [{low:g}, {high:g}]"
        if not valid_value:
            return name, allowed
    return None


def _fold_weight(alpha: float) -> float:
    """``w`` of the validity cone: ``alpha / (1 - alpha)`` up to 0.5, ``(1 - alpha) / alpha`` above."""
    return alpha / (1.0 - alpha) if alpha <= 0.5 else (1.0 - alpha) / alpha


def valid(model: str, coeffs: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Mask (N,) of points (N, 3) the model projects one-to-one (``z > -w * distance``).

    ds: the second (unified) projection is one-to-one on the cone ``s > -w1 d2`` of the shifted
    point ``(x, y, s)``; pulled back through the shift (``(c + xi)^2 = w1^2 (1 + 2 xi c + xi^2)`` for the
    boundary's ``c = z / d1``) that cone is ``z > -w2 d1`` with ``w2 = xi (1 - w1^2) + w1 sqrt(1 - xi^2 (1 - w1^2))``.
    """
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    if model == "omni":  # den > 0 (xi <= 1), or short of the fold at z / |p| = -1 / xi (xi > 1)
        (xi,) = coeffs.tolist()
        return z > -min(xi, 1.0 / xi if xi > 0 else 0.0) * np.sqrt(x * x + y * y + z * z)
    if model == "ds":
        xi, alpha = coeffs.tolist()
        w1 = _fold_weight(alpha)
        w2 = xi * (1.0 - w1 * w1) + w1 * np.sqrt(1.0 - xi * xi * (1.0 - w1 * w1))
        return z > -w2 * np.sqrt(x * x + y * y + z * z)
    alpha, beta = coeffs.tolist()
    return z > -_fold_weight(alpha) * np.sqrt(beta * (x * x + y * y) + z * z)


def denominator(model: str, coeffs: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``den`` (N,) of points (N, 3)."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    r2 = x * x + y * y
    if model == "omni":
        return z + coeffs[0] * np.sqrt(r2 + z * z)
    if model == "ds":
        xi, alpha = coeffs.tolist()
        s = xi * np.sqrt(r2 + z * z) + z
        return alpha * np.sqrt(r2 + s * s) + (1.0 - alpha) * s
    alpha, beta = coeffs.tolist()
    return alpha * np.sqrt(beta * r2 + z * z) + (1.0 - alpha) * z


def denominator_jacobians(model: str, coeffs: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``den`` (N,), ``d den / d p`` (N, 3) and ``d den / d coeffs`` (N, C) of points (N, 3)."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    r2 = x * x + y * y
    d_coeffs = np.empty((len(p), len(COEFFICIENTS[model])))
    if model == "omni":
        (xi,) = coeffs.tolist()
        d = np.sqrt(r2 + z * z)
        d_point = xi * p / d[:, None]
        d_point[:, 2] += 1.0
        d_coeffs[:, 0] = d
        return z + xi * d, d_point, d_coeffs
    if model == "ds":
        xi, alpha = coeffs.tolist()
        d1 = np.sqrt(r2 + z * z)
        s = xi * d1 + z
        d2 = np.sqrt(r2 + s * s)
        den = alpha * d2 + (1.0 - alpha) * s
        ds_dp = xi * p / d1[:, None]
        ds_dp[:, 2] += 1.0
        dd2_dp = (s[:, None] * ds_dp + np.stack([x, y, np.zeros_like(z)], axis=1)) / d2[:, None]
        d_point = alpha * dd2_dp + (1.0 - alpha) * ds_dp
        d_coeffs[:, 0] = (alpha * s / d2 + (1.0 - alpha)) * d1  # d den / d xi (s moves by d1 per unit xi)
        d_coeffs[:, 1] = d2 - s
        return den, d_point, d_coeffs
    alpha, beta = coeffs.tolist()
    rho = np.sqrt(beta * r2 + z * z)
    den = alpha * rho + (1.0 - alpha) * z
    d_point = alpha * np.stack([beta * x, beta * y, z], axis=1) / rho[:, None]
    d_point[:, 2] += 1.0 - alpha
    d_coeffs[:, 0] = rho - z
    d_coeffs[:, 1] = alpha * r2 / (2.0 * rho)
    return den, d_point, d_coeffs


def unproject(model: str, coeffs: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit bearing vectors (N, 3) of projected coordinates ``m = ((u - cx) / fx, (v - cy) / fy)`` (N, 2),
    and a mask (N,) of those inside the image of the valid domain (the others are NaN)."""
    mx, my = m[:, 0], m[:, 1]
    r2 = mx * mx + my * my
    if model == "omni":  # the point on the unit sphere: Mei's lifting
        (xi,) = coeffs.tolist()
        inside = r2 <= 1.0 / (xi * xi - 1.0) if xi > 1.0 else np.ones(len(m), dtype=bool)
        r2 = np.where(inside, r2, 0.0)
        scale = (xi + np.sqrt(1.0 + (1.0 - xi * xi) * r2)) / (1.0 + r2)
        rays = scale[:, None] * np.stack([mx, my, np.ones_like(mx)], axis=1)
        rays[:, 2] -= xi
    elif model == "ds":
        xi, alpha = coeffs.tolist()
        inside = r2 <= 1.0 / (2.0 * alpha - 1.0) if alpha > 0.5 else np.ones(len(m), dtype=bool)
        r2 = np.where(inside, r2, 0.0)
        mz = (1.0 - alpha * alpha * r2) / (alpha * np.sqrt(1.0 - (2.0 * alpha - 1.0) * r2) + 1.0 - alpha)
        scale = (mz * xi + np.sqrt(mz * mz + (1.0 - xi * xi) * r2)) / (mz * mz + r2)
        rays = scale[:, None] * np.stack([mx, my, mz], axis=1)
        rays[:, 2] -= xi
    else:
        alpha, beta = coeffs.tolist()
        inside = r2 <= 1.0 / (beta * (2.0 * alpha - 1.0)) if alpha > 0.5 else np.ones(len(m), dtype=bool)
        r2 = np.where(inside, r2, 0.0)
        mz = (1.0 - beta * alpha * alpha * r2) / (alpha * np.sqrt(1.0 - (2.0 * alpha - 1.0) * beta * r2) + 1.0 - alpha)
        rays = np.stack([mx, my, mz], axis=1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    rays[~inside] = np.nan
    return rays, inside

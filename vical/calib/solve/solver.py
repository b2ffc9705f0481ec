"""Levenberg-Marquardt and marginal covariances, with GTSAM failures turned into ``CalibrationError``."""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from vical.calib.errors import CalibrationError


@dataclass(frozen=True)
class Solution:
    """Optimised values with the solver's facts.

    Attributes:
        values: the optimised ``gtsam.Values``.
        iterations: LM iterations.
        status: ``"converged"`` or ``"max_iterations"``.
        error: final graph error (0.5 * sum of squared whitened residuals).
    """

    values: gtsam.Values
    iterations: int
    status: str
    error: float


# Levenberg-Marquardt's damping schedule (GTSAM's defaults): lambda starts small, is divided by the
# factor after a step that lowers the error and multiplied by it after one that does not; the
# solve stops when lambda exceeds the upper bound (no step lowers the error any more), or when a step
# that does not lower the error changes it by no more than RELATIVE_ERROR_TOL: the minimum, to the
# error's own rounding (stronger damping only shortens the same step: measured, 13 of 17 error
# evaluations of a rolling-shutter solve went to raising lambda there).
LAMBDA_INITIAL = 1e-5
LAMBDA_FACTOR = 10.0
LAMBDA_UPPER_BOUND = 1e5
RELATIVE_ERROR_TOL = 1e-8
ABSOLUTE_ERROR_TOL = 1e-12


def optimize(
    graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values, max_iterations: int = 50, what: str = "calibration"
) -> Solution:
    """Levenberg-Marquardt from ``initial``: GTSAM linearisation and multifrontal elimination, damping here.

    The loop runs in Python so that every ``gtsam.Values`` the graph sees is a Python object: GTSAM's
    own optimizer hands its internal values to each Python factor as a fresh copy of all variables,
    which made the per-frame corner factors cost O(frames^2).

    Raises:
        CalibrationError: when the linear system is singular (an unobservable parameter) or the
            solution is not finite.
    """
    try:
        return _levenberg_marquardt(graph, gtsam.Values(initial), max_iterations)
    except RuntimeError as exc:
        raise CalibrationError(
            f"the {what} problem is singular: some parameter is not constrained by the data ({_first_line(exc)}); "
            "record more varied motion (rotate about all axes, tilt the target) and check the inputs"
        ) from exc
    except _Diverged:
        raise CalibrationError(
            f"the {what} diverged (non-finite residuals); check the initial guess and the data"
        ) from None


class _Diverged(Exception):
    pass


def _damping(values: gtsam.Values) -> list[tuple[int, int]]:
    """(key, tangent dimension) of every variable."""
    zero = values.zeroVectors()
    return [(key, zero.at(key).size) for key in values.keys()]  # noqa: SIM118 (gtsam.Values is not iterable)


def _damped(linear: gtsam.GaussianFactorGraph, variables: list[tuple[int, int]], lam: float):
    damped = linear.clone()
    root = np.sqrt(lam)
    for key, dim in variables:
        damped.push_back(
            gtsam.JacobianFactor(key, root * np.eye(dim), np.zeros(dim), gtsam.noiseModel.Unit.Create(dim))
        )
    return damped


def _solve_linear(system: gtsam.GaussianFactorGraph, ordering: gtsam.Ordering) -> gtsam.VectorValues:
    """The least-squares step: Cholesky, or QR where the information spans too many decades for it."""
    try:
        return system.optimize(ordering)
    except RuntimeError:
        return system.eliminateMultifrontal(ordering, gtsam.EliminateQR).optimize()


def _levenberg_marquardt(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, max_iterations: int) -> Solution:
    error = float(graph.error(values))
    if not np.isfinite(error):
        raise _Diverged
    variables = _damping(values)
    lam, iterations, ordering = LAMBDA_INITIAL, 0, None
    while iterations < max_iterations:
        linear = graph.linearize(values)
        if ordering is None:
            ordering = gtsam.Ordering.ColamdGaussianFactorGraph(linear)
        while lam <= LAMBDA_UPPER_BOUND:
            candidate = values.retract(_solve_linear(_damped(linear, variables, lam), ordering))
            new_error = float(graph.error(candidate))
            if np.isfinite(new_error) and new_error < error:
                break
            if np.isfinite(new_error) and new_error - error <= RELATIVE_ERROR_TOL * error:
                return Solution(values, iterations, "converged", error)  # no lower error within its rounding
            lam *= LAMBDA_FACTOR
        else:
            return Solution(values, iterations, "converged", error)  # no step lowers the error: a minimum
        iterations += 1
        decrease = error - new_error
        values, error, lam = candidate, new_error, lam / LAMBDA_FACTOR
        if decrease <= ABSOLUTE_ERROR_TOL or decrease <= RELATIVE_ERROR_TOL * (error + decrease):
            return Solution(values, iterations, "converged", error)
    return Solution(values, iterations, "max_iterations", error)


SINGULAR_EIGENVALUE = 1e-12  # relative to 1 in the equilibrated marginal information: a free direction


def linear_covariance(linear: gtsam.GaussianFactorGraph, values: gtsam.Values, keys: list[int]) -> np.ndarray:
    """Joint marginal covariance of ``keys`` in the linearised graph ``linear`` (at ``values``).

    Every other variable is eliminated (QR: accurate where the information spans many decades, as
    with tiny IMU random walks); what remains is the keys' marginal information, a small dense
    matrix that is inverted (``values`` gives the keys' dimensions through the remaining graph).
    """
    try:
        order = gtsam.Ordering.ColamdConstrainedLastGaussianFactorGraph(linear, keys)
        others = [order.at(i) for i in range(order.size() - len(keys))]  # the keys come last
        _, remaining = linear.eliminatePartialMultifrontal(_ordering(others), gtsam.EliminateQR)
        information = remaining.augmentedHessian(_ordering(keys))[:-1, :-1]
        return _inverse(information)
    except (RuntimeError, np.linalg.LinAlgError) as exc:
        raise CalibrationError(
            f"the uncertainty cannot be computed: the information matrix is singular ({_first_line(exc)}); "
            "some parameter is not observable from this data"
        ) from exc


def _inverse(information: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive definite information matrix, equilibrated (its units may differ by decades).

    Raises:
        numpy.linalg.LinAlgError: when a direction is (numerically) free.
    """
    scale = 1.0 / np.sqrt(np.maximum(np.diag(information), np.finfo(float).tiny))
    equilibrated = information * np.outer(scale, scale)
    eigenvalues, vectors = np.linalg.eigh(0.5 * (equilibrated + equilibrated.T))
    if not eigenvalues[0] > SINGULAR_EIGENVALUE * eigenvalues[-1]:
        raise np.linalg.LinAlgError("Indeterminate: the marginal information has a free direction")
    return (vectors / eigenvalues) @ vectors.T * np.outer(scale, scale)


def determined(covariance: np.ndarray) -> bool:
    """Whether a covariance computed without checking for free directions (e.g. from a sparse LU of the information)
    has none: finite, and its equilibrated eigenvalues within ``SINGULAR_EIGENVALUE`` of each other, as
    ``linear_covariance`` requires of the information."""
    if not np.all(np.isfinite(covariance)):
        return False
    diagonal = np.diag(covariance)
    if not np.all(diagonal > 0):
        return False
    scale = 1.0 / np.sqrt(diagonal)
    eigenvalues = np.linalg.eigvalsh(0.5 * (covariance + covariance.T) * np.outer(scale, scale))
    return bool(eigenvalues[0] > SINGULAR_EIGENVALUE * eigenvalues[-1])


UNOBSERVABLE_DAMPING = 1e-6  # [whitened information] added to every variable when the information is singular
UNOBSERVABLE_SIGMA = 1e2  # a damped 1-sigma this large (in the tangent's unit) means: not determined by the data


def covariance_or_unobservable(linear: gtsam.GaussianFactorGraph, values: gtsam.Values, keys: list[int]) -> np.ndarray:
    """``linear_covariance``, or where the information is singular, NaN for the directions the data leave free.

    A tiny damping of every variable makes the information invertible; parameters whose damped
    1-sigma stays huge are the unobservable ones (their rows and columns become NaN), the others
    keep their (practically undamped) covariance. The estimate itself is never lost.
    """
    try:
        return linear_covariance(linear, values, keys)
    except CalibrationError:
        covariance = linear_covariance(_damped(linear, _damping(values), UNOBSERVABLE_DAMPING), values, keys)
        free = np.sqrt(np.abs(np.diag(covariance))) > UNOBSERVABLE_SIGMA
        covariance[free, :] = np.nan
        covariance[:, free] = np.nan
        return covariance


def _ordering(keys: list[int]) -> gtsam.Ordering:
    ordering = gtsam.Ordering()
    for key in keys:
        ordering.push_back(key)
    return ordering


def _first_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__

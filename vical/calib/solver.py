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
# solve stops when lambda exceeds the upper bound (no step lowers the error any more).
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
            candidate = values.retract(_damped(linear, variables, lam).optimize(ordering))
            new_error = float(graph.error(candidate))
            if np.isfinite(new_error) and new_error < error:
                break
            lam *= LAMBDA_FACTOR
        else:
            return Solution(values, iterations, "converged", error)  # no step lowers the error: a minimum
        iterations += 1
        decrease = error - new_error
        values, error, lam = candidate, new_error, lam / LAMBDA_FACTOR
        if decrease <= ABSOLUTE_ERROR_TOL or decrease <= RELATIVE_ERROR_TOL * (error + decrease):
            return Solution(values, iterations, "converged", error)
    return Solution(values, iterations, "max_iterations", error)


def joint_covariance(
    graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, keys: list[int], ordering: list[int] | None = None
) -> np.ndarray:
    """Joint marginal covariance (in the keys' tangent spaces, in order) of the graph linearised at ``values``.

    The graph is eliminated with the requested keys last (COLAMD constrained last, or the given
    ``ordering`` that must end with them), so their joint marginal is usually the inverse information
    of the Bayes tree's root clique: several times cheaper than ``gtsam.Marginals``, which is the
    fallback when the elimination split the keys over several cliques.
    """
    try:
        linear = graph.linearize(values)
        if ordering is None:
            order = gtsam.Ordering.ColamdConstrainedLastGaussianFactorGraph(linear, keys)
        else:
            order = _ordering(ordering)
        roots = [r.conditional() for r in linear.eliminateMultifrontal(order, gtsam.EliminateQR).roots()]
        holding = [c for c in roots if set(keys) <= set(c.keys())]
        if not holding:  # the elimination left them in separate cliques: the general (slower) way
            return gtsam.Marginals(linear, values).jointMarginalCovariance(keys).fullMatrix()
        return _root_covariance(holding[0], values, keys)
    except (RuntimeError, np.linalg.LinAlgError) as exc:
        raise CalibrationError(
            f"the uncertainty cannot be computed: the information matrix is singular ({_first_line(exc)}); "
            "some parameter is not observable from this data"
        ) from exc


def _root_covariance(conditional: gtsam.GaussianConditional, values: gtsam.Values, keys: list[int]) -> np.ndarray:
    """Covariance of ``keys``, eliminated last and so the trailing block of the root clique's ``R``.

    With ``R = [[R11, R12], [0, R22]]`` the marginal information of the trailing variables is
    ``R22^T R22``, so only the small ``R22`` is inverted.
    """
    zero = values.zeroVectors()
    offsets, start = {}, 0
    root_keys = list(conditional.keys())  # a GaussianConditional, not a dict
    for key in root_keys:
        offsets[key] = (start, start + zero.at(key).size)
        start += zero.at(key).size
    missing = [k for k in keys if k not in offsets]
    if missing:
        raise CalibrationError(f"internal: keys {missing} were not eliminated last")
    first = min(offsets[k][0] for k in keys)
    if sum(offsets[k][1] - offsets[k][0] for k in keys) != start - first:
        raise CalibrationError("internal: the requested keys are not the trailing block of the root clique")
    R22 = conditional.R()[first:, first:]
    R22_inv = np.linalg.solve(R22, np.eye(len(R22)))
    covariance = R22_inv @ R22_inv.T
    idx = np.concatenate([np.arange(offsets[k][0] - first, offsets[k][1] - first) for k in keys])
    return covariance[np.ix_(idx, idx)]


def _ordering(keys: list[int]) -> gtsam.Ordering:
    ordering = gtsam.Ordering()
    for key in keys:
        ordering.push_back(key)
    return ordering


def _first_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__

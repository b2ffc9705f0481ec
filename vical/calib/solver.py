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


def optimize(
    graph: gtsam.NonlinearFactorGraph,
    initial: gtsam.Values,
    max_iterations: int = 50,
    what: str = "calibration",
    ordering: list[int] | None = None,
) -> Solution:
    """Levenberg-Marquardt (multifrontal Cholesky) from ``initial``.

    The elimination ``ordering`` (keys, first eliminated first) defaults to COLAMD.

    Raises:
        CalibrationError: when the linear system is singular (an unobservable parameter) or the
            solution is not finite.
    """
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(1e-8)
    params.setAbsoluteErrorTol(1e-12)
    if ordering is None:
        params.setOrderingType("COLAMD")
    else:
        params.setOrdering(_ordering(ordering))
    try:
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        values = optimizer.optimize()
    except RuntimeError as exc:
        raise CalibrationError(
            f"the {what} problem is singular: some parameter is not constrained by the data ({_first_line(exc)}); "
            "record more varied motion (rotate about all axes, tilt the target) and check the inputs"
        ) from exc
    error = float(graph.error(values))
    if not np.isfinite(error):
        raise CalibrationError(f"the {what} diverged (non-finite residuals); check the initial guess and the data")
    iterations = int(optimizer.iterations())
    status = "max_iterations" if iterations >= max_iterations else "converged"
    return Solution(values, iterations, status, error)


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
        roots = [r.conditional() for r in linear.eliminateMultifrontal(order).roots()]
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

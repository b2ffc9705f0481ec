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


def joint_covariance(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, keys: list[int]) -> np.ndarray:
    """Joint marginal covariance (in the keys' tangent spaces, in order) from the graph linearised at ``values``."""
    try:
        marginals = gtsam.Marginals(graph.linearize(values), values)
        if len(keys) == 1:
            return np.asarray(marginals.marginalCovariance(keys[0]))
        return np.asarray(marginals.jointMarginalCovariance(gtsam.KeyVector(keys)).fullMatrix())
    except RuntimeError as exc:
        raise CalibrationError(
            f"the uncertainty cannot be computed: the information matrix is singular ({_first_line(exc)}); "
            "some parameter is not observable from this data"
        ) from exc


def _ordering(keys: list[int]) -> gtsam.Ordering:
    ordering = gtsam.Ordering()
    for key in keys:
        ordering.push_back(key)
    return ordering


def _first_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__

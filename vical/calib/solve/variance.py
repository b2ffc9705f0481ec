"""A posteriori noise levels: the variance factor of each sensor from its own residuals.

The declared noise is often wrong on real sensors: Kalibr users inflate IMU noise densities 10-30x,
and real corner noise is not the simulator's. Each sensor's variance factor is its whitened
chi-square over its redundancy (variance component estimation)::

    s_g^2 = chi2_g / r_g,    r_g = n_g - tr(H^-1 H_g)

with ``n_g`` the sensor's residual dimension and ``tr(H^-1 H_g)`` the degrees of freedom its
information spends on the parameters. The trace is the derivative of ``log det(H + (t - 1) H_g)``
at ``t = 1``: two eliminations of the linearised graph with the sensor's factors weighted by
``1 +- eps`` (``GaussianBayesTree.logDeterminant``), exact up to ``eps^2``.
"""

from __future__ import annotations

from collections.abc import Sequence

import gtsam
import numpy as np

EPS = 1e-3  # relative change of a sensor's weight for the central difference


def _reweighted(linear: gtsam.GaussianFactorGraph, group: set[int], weight: float) -> gtsam.GaussianFactorGraph:
    """The linear graph with the (whitened) factors ``group`` weighted by ``weight`` (information x weight)."""
    out = gtsam.GaussianFactorGraph()
    for i in range(linear.size()):
        factor = linear.at(i)
        if i in group:
            factor = gtsam.JacobianFactor(factor)
            factor.setModel(False, np.full(factor.rows(), 1.0 / np.sqrt(weight)))
        out.push_back(factor)
    return out


def _log_det(linear: gtsam.GaussianFactorGraph, ordering: gtsam.Ordering) -> float:
    """``log det H`` of the graph's information ``H``: twice the log-determinant of its square root.

    Multifrontal Cholesky; where that breaks down (information spanning too many decades, as with
    tiny IMU random walks) sequential QR, whose ``R`` may have negative diagonal entries.
    """
    try:
        value = 2.0 * linear.eliminateMultifrontal(ordering).logDeterminant()
        if np.isfinite(value):
            return value
    except RuntimeError:
        pass
    net = linear.eliminateSequential(ordering, gtsam.EliminateQR)
    return 2.0 * sum(float(np.sum(np.log(np.abs(np.diag(net.at(i).R()))))) for i in range(net.size()))


def used_dof(linear: gtsam.GaussianFactorGraph, group: Sequence[int], ordering: gtsam.Ordering) -> float:
    """``tr(H^-1 H_g)``: the parameters' degrees of freedom the factors ``group`` (indices in ``linear``) pin."""
    chosen = set(group)
    up = _log_det(_reweighted(linear, chosen, 1.0 + EPS), ordering)
    down = _log_det(_reweighted(linear, chosen, 1.0 - EPS), ordering)
    return (up - down) / (2.0 * EPS)


def variance_factor(chi2: float, residuals: int, used: float) -> float:
    """``s^2 = chi2 / (n - used)``; NaN when the sensor has no redundancy left."""
    redundancy = residuals - used
    return float(chi2 / redundancy) if redundancy > 0.5 else float("nan")

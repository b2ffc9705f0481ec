"""Cluster-robust covariance: how much the parameters move with the data over time, not only under the noise model.

Unmodelled effects (a rolling shutter, detector biases, IMU errors that are not white noise) make
the residuals of neighbouring frames agree with each other. The noise model then counts the same
information many times and its covariance is too small: on real recordings the printed 1-sigma of
the extrinsic was 10-60x smaller than the spread between calibrations. The sandwich estimator
clustered by time windows (Huber-White, the analytic jackknife over windows) measures instead how
much each window pulls on the parameters::

    Sigma_robust = H^-1 (sum_c g_c g_c^T) H^-1 * C / (C - 1),    g_c = A_c^T r_c

with ``A``, ``r`` the whitened Jacobian and residuals of the linearised graph at the solution,
``H = A^T A``, and ``c`` the ``C`` windows. ``sandwich_covariances`` computes it beside the covariance
under the measured noise levels, from the same factorisation. The covariance a calibration reports is the
latter, widened along every direction where the robust one is larger (``widen``), never narrowed: with few
windows the robust estimate is noisy.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import gtsam
import numpy as np
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg


def _offsets(values: gtsam.Values) -> tuple[int, dict[int, np.ndarray]]:
    """Total tangent dimension and each key's column indices (keys in sorted order)."""
    zero = values.zeroVectors()
    columns, start = {}, 0
    for key in sorted(values.keys()):
        dim = zero.at(key).size
        columns[key] = np.arange(start, start + dim)
        start += dim
    return start, columns


def _normal_equations(
    linear: gtsam.GaussianFactorGraph,
    columns: dict[int, np.ndarray],
    P: int,
    clusters: np.ndarray,
    variance_scale: np.ndarray,
):
    """The information ``H = A^T A`` (P, P, sparse), the noise's information ``M = sum_k s_k A_k^T A_k`` (P, P,
    sparse; ``s_k`` the true variance of factor k over the one it is weighted with) and each window's gradient
    ``A_c^T b_c`` (P, C)."""
    ids = np.unique(clusters[clusters >= 0])
    window = np.searchsorted(ids, clusters)
    rows, cols, entries, scales = [], [], [], []
    gradients = np.zeros((P, len(ids)))
    for k in range(linear.size()):
        factor = linear.at(k)
        A, b = factor.jacobian()
        index = np.concatenate([columns[key] for key in factor.keys()])  # noqa: SIM118 (a factor is no dict)
        rows.append(np.repeat(index, len(index)))
        cols.append(np.tile(index, len(index)))
        entries.append((A.T @ A).ravel())
        scales.append(np.full(len(index) ** 2, variance_scale[k]))
        if clusters[k] >= 0:
            gradients[index, window[k]] += A.T @ b
    where = (np.concatenate(rows), np.concatenate(cols))
    H = scipy.sparse.csc_matrix((np.concatenate(entries), where), shape=(P, P))
    M = scipy.sparse.csc_matrix((np.concatenate(entries) * np.concatenate(scales), where), shape=(P, P))
    return H, M, gradients


def _inverse_columns(H: scipy.sparse.csc_matrix, theta: np.ndarray) -> np.ndarray | None:
    """``H^-1 E_theta`` (P, k), or None for a singular ``H`` (Jacobi-equilibrated sparse LU)."""
    scale = 1.0 / np.sqrt(np.maximum(H.diagonal(), np.finfo(float).tiny))
    try:
        lu = scipy.sparse.linalg.splu((scipy.sparse.diags(scale) @ H @ scipy.sparse.diags(scale)).tocsc())
    except RuntimeError:
        return None
    rhs = np.zeros((H.shape[0], len(theta)))
    rhs[theta, np.arange(len(theta))] = scale[theta]
    return scale[:, None] * lu.solve(rhs)


class Covariances(NamedTuple):
    """The keys' covariances from one factorisation of the information (``sandwich_covariances``)."""

    model: np.ndarray  # under the noise model the solve weighted with: the keys' block of H^-1
    scaled: np.ndarray  # under the measured noise levels
    robust: np.ndarray | None  # cluster-robust (None with fewer than two windows)


def sandwich_covariances(
    linear: gtsam.GaussianFactorGraph,
    values: gtsam.Values,
    keys: Sequence[int],
    clusters: np.ndarray,
    variance_scale: np.ndarray,
) -> Covariances | None:
    """The keys' covariance under the noise model, under the measured noise levels and the cluster-robust one, of a
    solve weighted by the declared noise (in the keys' tangent spaces, in order; the graph linearised at the
    solution ``values``).

    A solve that weighs its factors by a noise whose true variance is ``s_k`` times the declared one has the
    covariance ``H^-1 (sum_k s_k H_k) H^-1`` (``H_k = A_k^T A_k``): exact for white noise of the measured
    levels (``vical.calib.solve.variance``). The cluster-robust one measures it from the residuals themselves.

    Args:
        linear: the graph linearised at the solution (whitened factors).
        values: the solution.
        keys: the variables whose joint covariance is wanted.
        clusters: (F,) the window of each factor of ``linear`` (-1: none, e.g. priors, which are no data).
        variance_scale: (F,) the true variance of each factor over its weight's (1: as declared).

    Returns:
        The three covariances; None when the information matrix is singular.
    """
    P, columns = _offsets(values)
    H, M, gradients = _normal_equations(linear, columns, P, clusters, variance_scale)
    theta = np.concatenate([columns[k] for k in keys])
    X = _inverse_columns(H, theta)  # H^-1 E_theta
    if X is None:
        return None
    model, scaled = X[theta], X.T @ (M @ X)
    C = gradients.shape[1]
    if C < 2:
        return Covariances(model, scaled, None)
    pulls = gradients.T @ X  # (C, k): each window's pull g_c^T H^-1 on the parameters
    return Covariances(model, scaled, C / (C - 1) * (pulls.T @ pulls))


def widen(model: np.ndarray, robust: np.ndarray) -> np.ndarray:
    """``model`` widened to ``robust`` along every direction where ``robust`` is larger.

    With ``model = L L^T``: ``L V max(Lambda, 1) V^T L^T``, ``V Lambda V^T`` the eigendecomposition of
    ``L^-1 robust L^-T``. Directions the model leaves unconstrained (non-finite) stay as they are.
    """
    if not np.all(np.isfinite(model)) or not np.all(np.isfinite(robust)):
        return model
    try:
        L = np.linalg.cholesky(model)
    except np.linalg.LinAlgError:
        return model
    inner = scipy.linalg.solve_triangular(L, scipy.linalg.solve_triangular(L, robust, lower=True).T, lower=True)
    eigenvalues, V = np.linalg.eigh(0.5 * (inner + inner.T))
    M = L @ V
    return (M * np.maximum(eigenvalues, 1.0)) @ M.T

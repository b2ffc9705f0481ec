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


class LinearSystem:
    """The normal equations of a graph linearised at its solution, factorised once for every covariance of it.

    ``H = A^T A`` (P, P, sparse) is the information, ``M = sum_k s_k A_k^T A_k`` the noise's information
    (``s_k`` the true variance of factor k over the one it is weighted with) and ``gradients`` (P, C) each window's
    ``A_c^T b_c`` (``A``, ``b``: the whitened Jacobian and right-hand side of ``linear``; ``b`` is minus the
    whitened error).
    """

    def __init__(
        self, linear: gtsam.GaussianFactorGraph, values: gtsam.Values, clusters: np.ndarray, variance_scale: np.ndarray
    ) -> None:
        self.size, self.columns = _offsets(values)
        ids = np.unique(clusters[clusters >= 0])
        self.window = np.where(clusters >= 0, np.searchsorted(ids, clusters), -1)  # each factor's window, -1: none
        rows, cols, entries, scales = [], [], [], []
        self.gradients = np.zeros((self.size, len(ids)))
        self.gradient = np.zeros(self.size)  # A^T b of every factor (zero at a converged solution)
        self.variance_scale = np.asarray(variance_scale, float)
        for k in range(linear.size()):
            factor = linear.at(k)
            A, b = factor.jacobian()
            index = self.factor_columns(factor)
            rows.append(np.repeat(index, len(index)))
            cols.append(np.tile(index, len(index)))
            entries.append((A.T @ A).ravel())
            scales.append(np.full(len(index) ** 2, variance_scale[k]))
            self.gradient[index] += A.T @ b
            if self.window[k] >= 0:
                self.gradients[index, self.window[k]] += A.T @ b
        where = (np.concatenate(rows), np.concatenate(cols))
        shape = (self.size, self.size)
        self.H = scipy.sparse.csc_matrix((np.concatenate(entries), where), shape=shape)
        self.M = scipy.sparse.csc_matrix((np.concatenate(entries) * np.concatenate(scales), where), shape=shape)
        self._scale = 1.0 / np.sqrt(np.maximum(self.H.diagonal(), np.finfo(float).tiny))
        try:  # Jacobi-equilibrated sparse LU
            self._lu = scipy.sparse.linalg.splu((scipy.sparse.diags(self._scale) @ self.H @ scipy.sparse.diags(
                self._scale)).tocsc())  # fmt: skip
        except RuntimeError:
            self._lu = None

    def factor_columns(self, factor) -> np.ndarray:
        """The columns of a linear factor's variables."""
        return np.concatenate([self.columns[key] for key in factor.keys()])  # noqa: SIM118 (a factor is no dict)

    @property
    def singular(self) -> bool:
        return self._lu is None

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``H^-1 rhs`` (P, k) of (P, k)."""
        return self._scale[:, None] * self._lu.solve(self._scale[:, None] * rhs)

    def key_columns(self, keys: Sequence[int]) -> np.ndarray:
        return np.concatenate([self.columns[k] for k in keys])


class Covariances(NamedTuple):
    """The keys' covariances from one factorisation of the information (``sandwich_covariances``)."""

    model: np.ndarray  # under the noise model the solve weighted with: the keys' block of H^-1
    scaled: np.ndarray  # under the measured noise levels
    robust: np.ndarray | None  # cluster-robust (None with fewer than two windows)


def sandwich_covariances(system: LinearSystem, keys: Sequence[int]) -> Covariances | None:
    """The keys' covariance under the noise model, under the measured noise levels and the cluster-robust one, of a
    solve weighted by the declared noise (in the keys' tangent spaces, in order).

    A solve that weighs its factors by a noise whose true variance is ``s_k`` times the declared one has the
    covariance ``H^-1 (sum_k s_k H_k) H^-1`` (``H_k = A_k^T A_k``): exact for white noise of the measured
    levels (``vical.calib.solve.variance``). The cluster-robust one measures it from the residuals themselves.

    Returns:
        The three covariances; None when the information matrix is singular.
    """
    if system.singular:
        return None
    theta = system.key_columns(keys)
    unit = np.zeros((system.size, len(theta)))
    unit[theta, np.arange(len(theta))] = 1.0
    X = system.solve(unit)  # H^-1 E_theta
    model, scaled = X[theta], X.T @ (system.M @ X)
    return Covariances(0.5 * (model + model.T), scaled, cluster_robust(system.gradients.T @ X))


def cluster_robust(pulls: np.ndarray) -> np.ndarray | None:
    """``C / (C - 1) sum_c p_c p_c^T`` of the windows' pulls ``p_c`` (C, k) on some parameters (None: C < 2)."""
    C = len(pulls)
    return None if C < 2 else C / (C - 1) * (pulls.T @ pulls)


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

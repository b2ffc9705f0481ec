"""Panda joint limits and damped-least-squares inverse kinematics on MuJoCo Jacobians.

The IK works on a scratch ``MjData`` (never the simulation's), so solving never disturbs the
running physics. Errors are measured for site ``ee`` (the camera body):
position [m] and rotation angle [rad] between the reached and the requested pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.linalg import _umath_linalg

from vical.geometry import so3_log
from vical.sim.settings import NUM_JOINTS, IKConfig


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits, (7,) each: position [rad], velocity [rad/s], acceleration [rad/s^2], torque [N m]."""

    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray
    tau_max: np.ndarray

    def inner(self, margin: float) -> tuple[np.ndarray, np.ndarray]:
        """Position range (q_lo, q_hi) shrunk by ``margin`` [rad] at both ends."""
        return self.q_min + margin, self.q_max - margin


# Franka Emika Panda datasheet ("Limits for Panda", Franka Control Interface documentation).
PANDA_LIMITS = JointLimits(
    q_min=np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973]),
    q_max=np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973]),
    v_max=np.array([2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100]),
    a_max=np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0]),
    tau_max=np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]),
)


@dataclass(frozen=True)
class IKResult:
    """Outcome of one inverse-kinematics solve.

    Attributes:
        q: (7,) [rad] joint positions (the best found, always within the joint ranges).
        success: both errors are below the configured tolerances.
        position_error: [m] distance between reached and requested ``ee`` positions.
        rotation_error: [rad] angle between reached and requested ``ee`` orientations.
        iterations: iterations spent over all attempts.
        attempts: attempts made (1 + restarts used).
    """

    q: np.ndarray
    success: bool
    position_error: float
    rotation_error: float
    iterations: int
    attempts: int


class PandaIK:
    """Damped-least-squares IK of site ``ee`` with joint-range clamping and seeded restarts.

    Each iteration solves ``(J J^T + lambda^2 I) y = e`` for the 6-D error ``e`` (world-frame
    position difference and rotation vector ``log(R_target R^T)``) and steps ``dq = J^T y``,
    scaled to at most ``max_step`` per joint and clamped into the joint ranges shrunk by
    ``margin``. The first attempt starts from the caller's configuration (so the solution stays
    close to it: short joint motions); restarts draw from ``rng`` configurations near it
    (``cfg.restart_spread``) or, with a spread of 0, uniformly over the joint ranges.
    """

    def __init__(self, model: mujoco.MjModel, cfg: IKConfig, limits: JointLimits, margin: float) -> None:
        self.model = model
        self.cfg = cfg
        self.q_lo, self.q_hi = limits.inner(margin)
        self._data = mujoco.MjData(model)
        self._site = model.site("ee").id
        self._jac = np.zeros((6, model.nv))
        self._eye6 = np.eye(6) * cfg.damping**2

    def forward(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``ee`` position (3,) [m] and rotation (3, 3) in the world at joint positions ``q`` (7,)."""
        p, R = self._kinematics(q)
        return p.copy(), R.copy()

    def _kinematics(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``ee`` position and rotation at ``q`` as views of the scratch data (valid until its next call)."""
        self._data.qpos[:NUM_JOINTS] = q
        mujoco.mj_kinematics(self.model, self._data)
        return self._data.site_xpos[self._site], self._data.site_xmat[self._site].reshape(3, 3)

    def _error(self, q: np.ndarray, p_target: np.ndarray, R_target: np.ndarray) -> np.ndarray:
        """(6,) position difference and rotation vector from ``ee`` at ``q`` to the target; leaves the kinematics
        of ``q`` in the scratch data (the Jacobian reuses them)."""
        p, R = self._kinematics(q)
        err = np.empty(6)
        np.subtract(p_target, p, out=err[:3])
        err[3:] = so3_log(R_target @ R.T)
        return err

    def _jacobian(self) -> np.ndarray:
        mujoco.mj_comPos(self.model, self._data)
        mujoco.mj_jacSite(self.model, self._data, self._jac[:3], self._jac[3:], self._site)
        return self._jac[:, :NUM_JOINTS]

    def _converged(self, err: np.ndarray) -> bool:
        return _norm(err[:3]) < self.cfg.position_tolerance and _norm(err[3:]) < self.cfg.rotation_tolerance

    def _step(self, J: np.ndarray, err: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Damped least-squares step (7,); joints at a limit that the step pushes outward are frozen.

        Without freezing, clamping would undo part of the step and the descent could stall.
        """
        dq = self._damped_step(J, err)
        at_low, at_high = q <= self.q_lo, q >= self.q_hi
        # count_nonzero: a flag test without the reduction machinery of any(), half its cost on 7 flags
        if not (np.count_nonzero(at_low) or np.count_nonzero(at_high)):  # the usual case: no joint at a limit
            return dq
        blocked = (at_low & (dq < 0)) | (at_high & (dq > 0))
        if np.count_nonzero(blocked):
            Jf = J * ~blocked
            dq = self._damped_step(Jf, err)
        return dq

    def _damped_step(self, J: np.ndarray, err: np.ndarray) -> np.ndarray:
        """``J^T (J J^T + lambda^2 I)^-1 e`` (7,)."""
        return J.T @ _solve(J @ J.T + self._eye6, err, signature="dd->d")

    def _attempt(self, q0: np.ndarray, T_target: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """One DLS descent from ``q0``: (q, final error (6,), iterations)."""
        q = np.clip(q0, self.q_lo, self.q_hi)
        p_target, R_target = T_target[:3, 3], T_target[:3, :3]
        err = self._error(q, p_target, R_target)
        for it in range(1, self.cfg.max_iterations + 1):
            J = self._jacobian()  # kinematics of q are in self._data from _error
            dq = self._step(J, err, q)
            largest = np.abs(dq).max()
            if largest > self.cfg.max_step:
                dq *= self.cfg.max_step / largest
            q = np.minimum(np.maximum(q + dq, self.q_lo), self.q_hi)
            err = self._error(q, p_target, R_target)
            if self._converged(err):
                return q, err, it
        return q, err, self.cfg.max_iterations

    def _restart(self, q_start: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        spread = self.cfg.restart_spread
        if spread == 0.0:
            return rng.uniform(self.q_lo, self.q_hi)
        return np.clip(q_start + rng.normal(0.0, spread, NUM_JOINTS), self.q_lo, self.q_hi)

    def solve(self, T_target: np.ndarray, q_start: np.ndarray, rng: np.random.Generator) -> IKResult:
        """Joint positions reaching ``T_target`` (4, 4) = requested ``T_world_ee``.

        Tries ``q_start`` (7,) first, then up to ``cfg.restarts`` random starts (class doc); returns the first
        converged solution, else the attempt with the smallest error (``success=False``). Bounded
        by ``(1 + restarts) * max_iterations`` iterations.
        """
        best: tuple[float, np.ndarray, np.ndarray] | None = None
        total = 0
        for attempt in range(1 + self.cfg.restarts):
            q0 = q_start if attempt == 0 else self._restart(q_start, rng)
            q, err, iterations = self._attempt(np.asarray(q0, dtype=float), T_target)
            total += iterations
            # Rank attempts by position + rotation error (1 mm counts as much as 1 mrad), plus 1 cm
            # per radian of joint motion, so an unreachable target does not trade a marginally
            # smaller error for a sweep into a far-away configuration.
            score = _norm(err[:3]) + _norm(err[3:]) + 0.01 * _norm(q - q_start)
            if best is None or score < best[0]:
                best = (score, q, err)
            if self._converged(err):
                break
        _, q, err = best
        return IKResult(
            q=q,
            success=self._converged(err),
            position_error=_norm(err[:3]),
            rotation_error=_norm(err[3:]),
            iterations=total,
            attempts=attempt + 1,
        )


# np.linalg.solve's own kernel (the same LAPACK gesv, the same floats) without its per-call checks, which cost
# more than the 6x6 solve itself in the IK's inner loop; the damped matrix is never singular (sim.ik.damping > 0).
_solve = _umath_linalg.solve1


def _norm(v: np.ndarray) -> float:
    """Euclidean norm of a vector: the float ``np.linalg.norm`` gives (sqrt of the dot product), without its
    overhead in the IK's inner loop."""
    return math.sqrt(v.dot(v))

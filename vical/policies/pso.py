"""A small particle swarm optimiser (minimisation in a box), seeded and vectorised over the swarm.

Each particle ``i`` keeps a position ``x_i``, a velocity ``v_i`` and its best position ``p_i``;
the swarm's best is ``g``. One iteration (Kennedy & Eberhart with inertia, Shi & Eberhart 1998):

    v_i <- w v_i + c1 r1 (p_i - x_i) + c2 r2 (g - x_i),   r1, r2 ~ U(0, 1) per component
    x_i <- x_i + v_i

The default ``w = 0.7298, c1 = c2 = 1.49618`` are Clerc's constriction values. Velocities are
clamped to ``max_velocity`` times the box width; a particle leaving the box is put back on the
bound and that velocity component is zeroed (absorbing walls), so every evaluated point is
inside the box. The run stops after ``iterations`` or when the best value has improved by less
than ``tolerance`` for ``patience`` iterations. The objective is any function of a (d,) array
returning a float; the random draws come from one seeded generator, so a run is deterministic
for a deterministic objective.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class PsoSettings:
    """Swarm settings.

    Attributes:
        particles: swarm size.
        iterations: maximum iterations after the initial evaluation.
        inertia: ``w``.
        cognitive: ``c1``, pull toward the particle's own best.
        social: ``c2``, pull toward the swarm's best.
        max_velocity: velocity clamp as a fraction of the box width per dimension.
        patience: stop after this many iterations without an improvement > ``tolerance`` (0: never).
        tolerance: improvement of the best value that counts (objective units).
        seed: seeds the initial swarm and the random factors.
    """

    particles: int = 20
    iterations: int = 50
    inertia: float = 0.7298
    cognitive: float = 1.49618
    social: float = 1.49618
    max_velocity: float = 0.5
    patience: int = 0
    tolerance: float = 1e-9
    seed: int = 0

    def __post_init__(self) -> None:
        if self.particles < 2 or self.iterations < 0:
            raise ValueError(f"PSO needs particles >= 2 and iterations >= 0, got {self.particles}, {self.iterations}")
        if not 0.0 <= self.inertia < 1.0 or self.cognitive < 0 or self.social < 0:
            raise ValueError(
                f"PSO needs 0 <= inertia < 1 and c1, c2 >= 0, got {self.inertia}, {self.cognitive}, {self.social}"
            )
        if not 0.0 < self.max_velocity <= 1.0 or self.patience < 0 or self.tolerance < 0:
            raise ValueError("PSO needs 0 < max_velocity <= 1, patience >= 0 and tolerance >= 0")


@dataclass(frozen=True)
class PsoProgress:
    """State after one iteration, passed to the progress callback.

    Attributes:
        iteration: 0 for the initial swarm, then 1, 2, ...
        best_value: the swarm's best objective so far.
        best_position: (d,) where it was found.
        values: (particles,) objective of each particle's current position.
        evaluations: objective calls so far.
        elapsed: [s] wall time since the start.
    """

    iteration: int
    best_value: float
    best_position: np.ndarray
    values: np.ndarray
    evaluations: int
    elapsed: float


@dataclass(frozen=True)
class PsoResult:
    """Outcome of a run.

    Attributes:
        position: (d,) best position found.
        value: its objective value.
        iterations: iterations run after the initial evaluation.
        evaluations: objective calls.
        stopped_early: the patience criterion ended the run.
        history: best value after each iteration (initial swarm first).
    """

    position: np.ndarray
    value: float
    iterations: int
    evaluations: int
    stopped_early: bool
    history: list[float] = field(default_factory=list)


def _check_bounds(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.asarray(lower, dtype=float).ravel(), np.asarray(upper, dtype=float).ravel()
    if lo.shape != hi.shape or not lo.size or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)):
        raise ValueError(f"PSO bounds must be finite arrays of one shape, got {lo.shape} and {hi.shape}")
    if not np.all(hi > lo):
        raise ValueError("PSO bounds need upper > lower in every dimension")
    return lo, hi


def _evaluate(objective: Callable[[np.ndarray], float], positions: np.ndarray) -> np.ndarray:
    """Objective of each row; NaN (a failed evaluation) counts as +inf so it never becomes a best."""
    values = np.array([float(objective(p.copy())) for p in positions])
    return np.where(np.isnan(values), np.inf, values)


def minimize(
    objective: Callable[[np.ndarray], float],
    lower: np.ndarray,
    upper: np.ndarray,
    settings: PsoSettings | None = None,
    callback: Callable[[PsoProgress], None] | None = None,
) -> PsoResult:
    """Minimise ``objective`` over the box ``[lower, upper]`` (both (d,)) with a particle swarm."""
    s = settings or PsoSettings()
    lo, hi = _check_bounds(lower, upper)
    rng = np.random.default_rng(s.seed)
    width = hi - lo
    vmax = s.max_velocity * width
    x = rng.uniform(lo, hi, (s.particles, lo.size))
    v = rng.uniform(-vmax, vmax, x.shape) * 0.1  # small start velocities: the first moves follow the bests
    start = time.perf_counter()
    f = _evaluate(objective, x)
    p, fp = x.copy(), f.copy()
    g = int(np.argmin(fp))
    history = [float(fp[g])]
    evaluations, stale, it = s.particles, 0, 0
    if callback:
        callback(PsoProgress(0, float(fp[g]), p[g].copy(), f, evaluations, time.perf_counter() - start))
    for it in range(1, s.iterations + 1):
        r1, r2 = rng.random(x.shape), rng.random(x.shape)
        v = s.inertia * v + s.cognitive * r1 * (p - x) + s.social * r2 * (p[g] - x)
        v = np.clip(v, -vmax, vmax)
        x = x + v
        outside = (x < lo) | (x > hi)
        x = np.clip(x, lo, hi)
        v[outside] = 0.0
        f = _evaluate(objective, x)
        evaluations += s.particles
        better = f < fp
        p[better], fp[better] = x[better], f[better]
        previous = history[-1]
        g = int(np.argmin(fp))
        history.append(float(fp[g]))
        stale = stale + 1 if previous - fp[g] <= s.tolerance else 0
        if callback:
            callback(PsoProgress(it, float(fp[g]), p[g].copy(), f, evaluations, time.perf_counter() - start))
        if s.patience and stale >= s.patience:
            return PsoResult(p[g].copy(), float(fp[g]), it, evaluations, True, history)
    return PsoResult(p[g].copy(), float(fp[g]), it, evaluations, False, history)

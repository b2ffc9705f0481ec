"""The MDP's action: one "direct transformation" of the end effector, and its inverse.

``A = [rho, theta, phi, alpha, beta, gamma]``: the translation has length ``rho`` [m] along the
direction of azimuth ``theta`` and polar angle ``phi`` [rad] (world axes: ``[sin phi cos theta,
sin phi sin theta, cos phi]``); ``alpha, beta, gamma`` [rad] are increments of the end effector's
world Euler angles roll, pitch, yaw (``docs/conventions.md``). With every component in
``[-scale, scale]`` and the authors' scales (``rho`` up to 0.3 m, angles up to ~pi/2), a negative
``rho`` reaches the directions below the horizontal plane.
"""

from __future__ import annotations

import numpy as np

ACTION_NAMES = ("rho", "theta", "phi", "alpha", "beta", "gamma")


def direction(theta: float, phi: float) -> np.ndarray:
    """(3,) unit vector of azimuth ``theta`` and polar angle ``phi`` [rad]."""
    return np.array([np.sin(phi) * np.cos(theta), np.sin(phi) * np.sin(theta), np.cos(phi)])


def action_to_step(action: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(translation (3) [m], euler_increment (3) [rad])`` of an action (6,)."""
    a = np.asarray(action, dtype=float)
    if a.shape != (6,) or not np.all(np.isfinite(a)):
        raise ValueError(f"an action is 6 finite numbers {list(ACTION_NAMES)}, got {a!r}")
    return a[0] * direction(a[1], a[2]), a[3:].copy()


def goal_offset(offset: np.ndarray, action: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """(6,) the workspace offset ``action`` (6,) heads for from ``offset`` (6,), clipped to the workspace ``bound`` (6,)
    (what the env and the collection runner execute)."""
    translation, euler_increment = action_to_step(action)
    return np.clip(np.asarray(offset, dtype=float) + np.r_[translation, euler_increment], -bound, bound)


def step_to_action(translation: np.ndarray, euler_increment: np.ndarray) -> np.ndarray:
    """The action (6,) whose step is ``translation`` (3) [m] and ``euler_increment`` (3) [rad].

    Its angles lie in ``theta, phi in [-pi/2, pi/2]`` (the range of the authors' action scale);
    ``rho`` is negative for translations pointing down. The caller bounds ``rho`` and the increments.
    """
    d = np.asarray(translation, dtype=float)
    rho = float(np.linalg.norm(d))
    action = np.zeros(6)
    action[3:] = euler_increment
    if rho == 0.0:
        return action
    if d[2] < 0:
        rho, d = -rho, -d
    u = d / abs(rho)
    phi = float(np.arccos(np.clip(u[2], -1.0, 1.0)))
    theta = float(np.arctan2(u[1], u[0]))
    if abs(theta) > np.pi / 2:  # the opposite azimuth with a mirrored polar angle is the same direction
        theta -= np.copysign(np.pi, theta)
        phi = -phi
    action[:3] = rho, theta, phi
    return action

"""Joint trajectories for one "direct transformation": quintic time scaling within the Panda's limits.

A motion from ``q0`` to ``q1`` follows the straight joint-space line with the minimum-jerk
(quintic) profile ``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5``, ``tau = t / T``: zero velocity and
acceleration at both ends, so the IMU sees no jumps. ``T`` is the shortest whole number of
physics steps for which every joint stays within its scaled velocity and acceleration limits.
The feed-forward torques come from MuJoCo's inverse dynamics on the same model.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.interpolate import CubicSpline

from vical.sim.kinematics import JointLimits
from vical.sim.settings import NUM_JOINTS

# Peaks of the quintic profile's derivatives on tau in [0, 1]: s' at tau = 1/2, |s''| at
# tau = 1/2 -+ sqrt(3)/6.
QUINTIC_PEAK_VELOCITY = 1.875
QUINTIC_PEAK_ACCELERATION = 10.0 / np.sqrt(3.0)


def quintic(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk profile ``s, ds/dtau, d2s/dtau2`` at ``tau`` (K,) in [0, 1]."""
    t = np.clip(tau, 0.0, 1.0)
    s = t**3 * (10.0 - 15.0 * t + 6.0 * t**2)
    ds = 30.0 * t**2 * (1.0 - t) ** 2
    dds = 60.0 * t * (1.0 - t) * (1.0 - 2.0 * t)
    return s, ds, dds


@dataclass(frozen=True)
class JointPlan:
    """A joint trajectory sampled at every physics step.

    Row ``k`` is the reference at ``k`` steps after the start (``k = 0 .. num_steps``).

    Attributes:
        q: (K + 1, 7) [rad] positions; qd: (K + 1, 7) [rad/s]; qdd: (K + 1, 7) [rad/s^2].
        timestep: physics step [s].
        move_steps: steps of the motion proper; the rest (to ``num_steps``) holds still.
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    timestep: float
    move_steps: int

    @property
    def num_steps(self) -> int:
        return len(self.q) - 1


def motion_steps(
    dq: np.ndarray,
    limits: JointLimits,
    velocity_scale: float,
    acceleration_scale: float,
    min_duration: float,
    timestep: float,
) -> int:
    """Fewest physics steps for a quintic move by ``dq`` (7,) [rad] within the scaled limits.

    Peak joint velocity is ``1.875 |dq| / T`` and peak acceleration ``5.77 |dq| / T^2``.
    """
    dq = np.abs(np.asarray(dq, dtype=float))
    t_vel = QUINTIC_PEAK_VELOCITY * dq / (velocity_scale * limits.v_max)
    t_acc = np.sqrt(QUINTIC_PEAK_ACCELERATION * dq / (acceleration_scale * limits.a_max))
    duration = max(min_duration, float(np.max(t_vel)), float(np.max(t_acc)))
    return int(np.ceil(duration / timestep - 1e-9))


def quintic_plan(q0: np.ndarray, q1: np.ndarray, move_steps: int, hold_steps: int, timestep: float) -> JointPlan:
    """Quintic move from ``q0`` to ``q1`` (7,) [rad] over ``move_steps``, then ``hold_steps`` at rest.

    Positions are the quintic sampled at every step. Velocities and accelerations are the finite
    differences that MuJoCo's semi-implicit Euler step realises exactly
    (``v_k = (q_k - q_{k-1}) / dt``, ``a_k = (v_{k+1} - v_k) / dt``), so a plant that follows the
    accelerations reproduces the sampled positions; each is the analytic derivative at some
    instant within the step, so the analytic limit checks bound them too.
    """
    k = np.arange(move_steps + hold_steps + 1)
    s, _, _ = quintic(k / max(move_steps, 1)) if move_steps else (np.ones(len(k)), None, None)
    q = np.asarray(q0, float) + s[:, None] * (np.asarray(q1, float) - np.asarray(q0, float))
    qd = np.zeros_like(q)
    qd[1:] = np.diff(q, axis=0) / timestep
    qdd = np.zeros_like(q)
    qdd[:-1] = np.diff(qd, axis=0) / timestep
    return JointPlan(q=q, qd=qd, qdd=qdd, timestep=timestep, move_steps=move_steps)


def _inverse_dynamics(model: mujoco.MjModel, scratch: mujoco.MjData, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray):
    """(N, 7) [N m] joint torques for states (N, 7) each, from MuJoCo's discrete-time inverse dynamics.

    Contacts are disabled while solving (plans are collision-checked) and the inverse is that of
    the discrete-time integrator (``mjENBL_INVDISCRETE``, with the implicit actuator damping), so
    the torque reproduces the step-to-step motion rather than the continuous-time ODE.
    """
    tau = np.empty((len(q), NUM_JOINTS))
    flags, enable = model.opt.disableflags, model.opt.enableflags
    model.opt.disableflags = flags | mujoco.mjtDisableBit.mjDSBL_CONTACT
    model.opt.enableflags = enable | mujoco.mjtEnableBit.mjENBL_INVDISCRETE
    try:
        for i in range(len(q)):
            scratch.qpos[:NUM_JOINTS] = q[i]
            scratch.qvel[:NUM_JOINTS] = qd[i]
            scratch.qacc[:NUM_JOINTS] = qdd[i]
            mujoco.mj_inverseSkip(model, scratch, mujoco.mjtStage.mjSTAGE_NONE, 1)
            tau[i] = scratch.qfrc_inverse[:NUM_JOINTS]
    finally:
        model.opt.disableflags, model.opt.enableflags = flags, enable
    return tau


def rest_torque(model: mujoco.MjModel, scratch: mujoco.MjData, q: np.ndarray) -> np.ndarray:
    """(7,) [N m] torque that holds joint positions ``q`` (7,) at rest (gravity and rig load)."""
    zero = np.zeros((1, NUM_JOINTS))
    return _inverse_dynamics(model, scratch, np.asarray(q, float)[None], zero, zero)[0]


def feedforward_torques(model: mujoco.MjModel, scratch: mujoco.MjData, plan: JointPlan, stride: int) -> np.ndarray:
    """(K + 1, 7) [N m] joint torques that realise the plan (MuJoCo inverse dynamics).

    Includes gravity, Coriolis and inertia with rotor armature and the sensor rig's mass.
    Inverse dynamics costs as much as a physics step, so during the move it runs every ``stride``
    steps (and at the move's last step) and a cubic spline fills the steps between: the torque of
    a quintic plan is smooth, the spline's error is far below what the PD feedback corrects.
    Rows after the move hold the goal at rest.
    """
    last = plan.move_steps
    tau = np.empty((plan.num_steps + 1, NUM_JOINTS))
    if last > 0:
        stride = max(1, min(stride, last // 8))  # at least 8 intervals so short moves keep their shape
        knots = np.unique(np.append(np.arange(0, last + 1, stride), last))
        tau_knots = _inverse_dynamics(model, scratch, plan.q[knots], plan.qd[knots], plan.qdd[knots])
        tau[: last + 1] = CubicSpline(knots, tau_knots, axis=0)(np.arange(last + 1))
    tau[last + 1 :] = rest_torque(model, scratch, plan.q[-1])
    if last == 0:
        tau[0] = tau[-1]
    return tau


@dataclass(frozen=True)
class MotionResult:
    """What one ``PandaSim.move_to`` did.

    Attributes:
        reached: the requested pose was executed as requested (IK converged, no clamping).
        clamped: the executed goal differs from the request (unreachable or colliding).
        message: why the target was clamped ('' when reached).
        T_requested: (4, 4) requested ``T_world_ee``.
        T_goal: (4, 4) the executed goal pose (forward kinematics of the goal joint positions).
        T_final: (4, 4) ``T_world_ee`` of the arm at the end (after any settling).
        q_goal: (7,) [rad] goal joint positions.
        duration: [s] motion time (without settling).
        settle_time: [s] rest appended at the goal.
        path_length: [m] sum of the end-effector's translation over all physics steps.
        rotation_length: [rad] sum of the end-effector's rotation angles over all physics steps.
        max_tracking_error: [rad] largest |q - q_reference| over joints and steps.
        position_margin: [rad] smallest distance of any joint to its position limit.
        velocity_margin: [rad/s] smallest gap between any joint speed and its velocity limit.
        num_steps: physics steps executed (motion + settling).
        t_start_ns, t_end_ns: simulated time [ns] at the start and end of the motion.
    """

    reached: bool
    clamped: bool
    message: str
    T_requested: np.ndarray
    T_goal: np.ndarray
    T_final: np.ndarray
    q_goal: np.ndarray
    duration: float
    settle_time: float
    path_length: float
    rotation_length: float
    max_tracking_error: float
    position_margin: float
    velocity_margin: float
    num_steps: int
    t_start_ns: int
    t_end_ns: int

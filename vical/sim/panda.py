"""``PandaSim``: the simulated Panda that executes end-effector pose steps in MuJoCo physics.

Timing. Simulated time is an integer count of physics steps; ``time_ns = step * timestep_ns``
(exact int64). ``mj_step`` first evaluates the current state (kinematics, sensors, forces:
``mj_forward``) and then integrates, so right after ``mj_step`` the derived quantities in
``data`` -- ``site_xpos``/``site_xmat``, ``xpos``, ``cam_xpos``, ``sensordata`` (accelerometer,
gyro) -- belong to the PRE-step state at ``time_ns - timestep_ns`` while ``qpos``/``qvel`` are
already at ``time_ns``. The ``on_step(sim, t_ns)`` callback runs after every physics step with
``t_ns`` the time of those derived quantities. Outside a motion (after ``reset`` and at the end of
``move_to``) ``mj_forward`` has run, so every quantity in ``data`` belongs to ``time_ns``.

Observers. A ``StepObserver`` (the sensor recorder) needs the poses of the IMU site and the end
effector at every physics step but live ``data`` only at a few steps (the camera exposures). Without
an ``on_step`` callback a motion runs in MuJoCo's ``rollout`` (the steps in C, no Python between
them), cut only after the steps the observer asked for; the poses come from the frame sensors of
panda.xml, which copy ``site_xpos``/``site_xmat``. ``rollout`` runs the same ``mj_step`` from the
same state and warm start, so both ways give the same floats (``tests/test_sim_motion.py``).

Control. Joint torques = feed-forward (inverse dynamics of the plan) + PD on the plan, both in
the affine actuators of panda.xml; the simulation never writes ``qpos`` while moving.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np
from mujoco import rollout

from vical.config_checks import ConfigError
from vical.data import NS_PER_S
from vical.geometry import euler_to_matrix, make_transform
from vical.sim.kinematics import PANDA_LIMITS, IKResult, PandaIK
from vical.sim.motion import JointPlan, MotionResult, feedforward_torques, motion_steps, quintic_plan, rest_torque
from vical.sim.scene import build_model, site_pose
from vical.sim.settings import NUM_JOINTS, SimConfig

StepCallback = Callable[["PandaSim", int], None]
_STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS
_FRAME_SENSORS = ("pos", "xaxis", "yaxis", "zaxis")  # per tracked site in panda.xml: <site>_<suffix>


@dataclass(frozen=True)
class StepPoses:
    """Poses of the tracked sites at consecutive physics steps of one motion.

    Row ``k`` holds the derived quantities of the step starting at ``t0_ns + k * step_ns``.

    Attributes:
        t0_ns: [ns] time of row 0; step_ns: [ns] physics step.
        imu_p: (K, 3) [m] and imu_R: (K, 9) (row-major ``site_xmat``) of site ``imu``.
        ee_p: (K, 3) [m] positions of site ``ee``.
    """

    t0_ns: int
    step_ns: int
    imu_p: np.ndarray
    imu_R: np.ndarray
    ee_p: np.ndarray


class StepObserver(Protocol):
    """Follows a motion: the poses of every step afterwards, live ``data`` at the steps it asks for."""

    def live_steps(self, t0_ns: int, num_steps: int, step_ns: int) -> list[int]:
        """Indices ``k`` (ascending, ``0 <= k < num_steps``) of the steps starting at ``t0_ns + k * step_ns`` at
        which ``on_live_step`` must see ``data``."""

    def on_live_step(self, sim: PandaSim, t_ns: int) -> None:
        """``data``'s derived quantities belong to the step starting at ``t_ns`` (as for ``on_step``)."""

    def on_steps(self, poses: StepPoses) -> None:
        """The poses of every step of the motion, after it."""


def _frame_sensor_columns(model: mujoco.MjModel, site: str) -> tuple[int, ...]:
    """Columns in ``sensordata`` of the frame sensors of ``site``: position, x, y and z axis."""
    return tuple(int(model.sensor(f"{site}_{suffix}").adr[0]) for suffix in _FRAME_SENSORS)


def _segments(num_steps: int, live: list[int]) -> list[tuple[int, int]]:
    """``[first, last)`` step ranges covering ``0 .. num_steps``, each live step the last of its range."""
    ends = [k + 1 for k in live if k + 1 < num_steps] + [num_steps]
    starts = [0, *ends[:-1]]
    return [(a, b) for a, b in zip(starts, ends, strict=True) if b > a]


def _check_pose(T: np.ndarray, name: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{name} must be a finite (4, 4) homogeneous transform, got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) <= 0:
        raise ValueError(f"{name}: the rotation block is not a rotation matrix (needs R^T R = I, det R = 1)")
    return T


def _geom_label(model: mujoco.MjModel, geom: int) -> str:
    """The geom's name, else the name of its body (unnamed collision capsules of the arm)."""
    return model.geom(geom).name or model.body(model.geom_bodyid[geom]).name


def rotation_path_length(R: np.ndarray) -> float:
    """Sum of rotation angles [rad] between consecutive rotations ``R`` (K, 3, 3)."""
    dR = np.einsum("kji,kjl->kil", R[:-1], R[1:])
    vee = np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0], dR[:, 1, 0] - dR[:, 0, 1]], axis=1)
    cos = (np.trace(dR, axis1=1, axis2=2) - 1.0) / 2.0
    return float(np.sum(np.arctan2(0.5 * np.linalg.norm(vee, axis=1), cos)))


class PandaSim:
    """The simulated Panda with its camera + IMU rig in front of the checkerboard.

    Attributes:
        cfg: the validated sim config.
        model, data: MuJoCo model and data of the scene.
        T_world_board: (4, 4) board pose (Kalibr board frame).
        limits: the Panda's joint limits.
        rng: the simulator's seeded Generator (IK restarts).
    """

    def __init__(self, cfg: SimConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else SimConfig()
        self.model, self.T_world_board = build_model(self.cfg)
        self.data = mujoco.MjData(self.model)
        self.limits = PANDA_LIMITS
        self._set_gains()
        self.ik = PandaIK(self.model, self.cfg.ik, self.limits, self.cfg.motion.joint_limit_margin)
        self._scratch = mujoco.MjData(self.model)
        self._frames = {site: _frame_sensor_columns(self.model, site) for site in ("imu", "ee")}
        self._geom_labels = [_geom_label(self.model, geom) for geom in range(self.model.ngeom)]
        self._home = self.model.key("home").id
        self.q_start = self._start_configuration()
        self.rng = np.random.default_rng(self.cfg.seed)
        self._step = 0
        self.reset()

    def _set_gains(self) -> None:
        kp = np.asarray(self.cfg.motion.kp)
        kd = np.asarray(self.cfg.motion.kd)
        self.model.actuator_biasprm[:NUM_JOINTS, 1] = -kp
        self.model.actuator_biasprm[:NUM_JOINTS, 2] = -kd
        self.model.actuator_forcerange[:NUM_JOINTS] = np.stack([-self.limits.tau_max, self.limits.tau_max], axis=1)

    def _start_configuration(self) -> np.ndarray:
        """(7,) joint positions of the start pose (``sim.start`` by IK from ``home``), checked for contacts.

        Raises ``ConfigError`` naming the key to change when the arm cannot reach the start pose or
        touches the board, its stand or itself there.
        """
        mujoco.mj_resetDataKeyframe(self.model, self.data, self._home)
        q = self.q
        start = self.cfg.start
        if start is not None:
            # A fixed generator: the start configuration must not depend on the episode's seed.
            ik = self.ik.solve(make_transform(euler_to_matrix(start.rpy), start.position), q, np.random.default_rng(0))
            if not ik.success:
                raise ConfigError(
                    f"sim.start: the arm cannot reach the start pose (position {list(start.position)} m, rpy "
                    f"{list(start.rpy)} rad); its closest pose is {1e3 * ik.position_error:.0f} mm / "
                    f"{np.degrees(ik.rotation_error):.1f} deg away; choose a pose within the Panda's reach "
                    "(about 0.85 m from its shoulder at 0.33 m height)"
                )
            q = ik.q
        touching = self.contact_at(q)
        if touching:
            key = "sim.start" if "board" not in touching and "stand" not in touching else "sim.board"
            raise ConfigError(
                f"{key}: at the start pose {touching} touch; move the board away from the arm "
                "(sim.board.distance, sim.board.offset) or choose another sim.start"
            )
        return q

    def contact_at(self, q: np.ndarray, ignore: frozenset[str] = frozenset()) -> str:
        """Names of the first pair of geoms in contact at joint positions ``q`` (7,), or '' when free.

        Pairs named in ``ignore`` (as returned here) do not count.
        """
        return next((pair for pair in self._contact_pairs(q) if pair not in ignore), "")

    def _contact_pairs(self, q: np.ndarray) -> list[str]:
        """The touching geom pairs at ``q`` in MuJoCo's contact order (deterministic)."""
        m, d = self.model, self._scratch
        d.qpos[:NUM_JOINTS] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        labels, contact = self._geom_labels, d.contact  # labels cached: naming a geom costs ~10 us
        pairs = zip(contact.geom1, contact.geom2, strict=True)
        return list(dict.fromkeys(f"{labels[a]} and {labels[b]}" for a, b in pairs))

    # ------------------------------------------------------------------ state
    def reset(self, seed: int | None = None) -> None:
        """Rest at the start pose at time 0 (reseeds ``rng`` when ``seed`` is given)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        mujoco.mj_resetDataKeyframe(self.model, self.data, self._home)
        self.data.qpos[:NUM_JOINTS] = self.q_start
        self._step = 0
        self.data.ctrl[:] = self._hold_ctrl(self.q)
        mujoco.mj_forward(self.model, self.data)

    @property
    def step_count(self) -> int:
        """Physics steps since ``reset``."""
        return self._step

    @property
    def timestep_ns(self) -> int:
        return self.cfg.physics.timestep_ns

    @property
    def time_ns(self) -> int:
        """Simulated time [ns] of the current state (``qpos``/``qvel``)."""
        return self._step * self.cfg.physics.timestep_ns

    def _steps_for(self, seconds: float) -> int:
        """Whole physics steps nearest to ``seconds`` [s]."""
        return round(seconds * NS_PER_S / self.timestep_ns)

    @property
    def q(self) -> np.ndarray:
        """(7,) [rad] current joint positions (a copy)."""
        return self.data.qpos[:NUM_JOINTS].copy()

    def ee_pose(self) -> np.ndarray:
        """``T_world_ee`` (4, 4) from ``data`` (the current state outside motions; see module doc)."""
        return site_pose(self.model, self.data, "ee")

    # ------------------------------------------------------------------ planning
    def solve_ik(self, T_world_ee: np.ndarray, q_start: np.ndarray | None = None) -> IKResult:
        """Joint positions for the end-effector pose ``T_world_ee`` (4, 4), starting near ``q_start``."""
        T = _check_pose(T_world_ee, "T_world_ee")
        return self.ik.solve(T, self.q if q_start is None else np.asarray(q_start, float), self.rng)

    def _hold_ctrl(self, q: np.ndarray) -> np.ndarray:
        """Actuator commands (7,) that hold ``q`` (7,) at rest (gravity feed-forward + PD set-point)."""
        return rest_torque(self.model, self._scratch, q) + np.asarray(self.cfg.motion.kp) * q

    def _ctrl_table(self, plan: JointPlan) -> np.ndarray:
        """(K + 1, 7) actuator commands ``tau_ff + kp q_ref + kd qd_ref`` (actuator = ctrl - kp q - kd qd)."""
        tau = feedforward_torques(self.model, self._scratch, plan, self.cfg.motion.feedforward_stride)
        return tau + np.asarray(self.cfg.motion.kp) * plan.q + np.asarray(self.cfg.motion.kd) * plan.qd

    def first_collision(self, q0: np.ndarray, q1: np.ndarray) -> tuple[float, str]:
        """Fraction along the joint line ``q0 -> q1`` of the first sampled configuration in contact.

        Returns ``(1.0, "")`` when all ``sim.motion.collision_samples`` samples are free, else
        the first colliding fraction and the names of the touching bodies. Contacts already present
        at ``q0`` do not count, so an arm that came to rest touching something can move away.
        """
        present = frozenset(self._contact_pairs(q0))
        for s in np.linspace(0.0, 1.0, self.cfg.motion.collision_samples)[1:]:
            touching = self.contact_at(q0 + s * (q1 - q0), ignore=present)
            if touching:
                return float(s), touching
        return 1.0, ""

    def _safe_goal(self, q0: np.ndarray, q_goal: np.ndarray) -> tuple[np.ndarray, str]:
        """Goal shortened to the last collision-free sample before the first contact, and why."""
        s_hit, bodies = self.first_collision(q0, q_goal)
        if s_hit >= 1.0:
            return q_goal, ""
        step = 1.0 / (self.cfg.motion.collision_samples - 1)
        s_safe = max(0.0, s_hit - step)
        message = f"path collides ({bodies}) at {100 * s_hit:.0f}% of the joint motion; stopped at {100 * s_safe:.0f}%"
        return q0 + s_safe * (q_goal - q0), message

    # ------------------------------------------------------------------ execution
    def move_to(
        self,
        T_world_ee_target: np.ndarray,
        on_step: StepCallback | None = None,
        settle_time: float | None = None,
        observer: StepObserver | None = None,
    ) -> MotionResult:
        """Move the end effector to ``T_world_ee_target`` (4, 4) in physics; never raises for infeasible targets.

        IK (closest reachable pose when unreachable), collision check along the joint path
        (stopping short of a contact), quintic plan within the scaled joint limits, execution
        with feed-forward + PD torques, then ``settle_time`` [s] (default ``sim.motion.settle_time``)
        at rest. ``on_step(sim, t_ns)`` runs after every physics step, ``observer`` follows the
        motion (see the module doc).
        """
        T_req = _check_pose(T_world_ee_target, "T_world_ee_target")
        settle = self.cfg.motion.settle_time if settle_time is None else float(settle_time)
        if not 0.0 <= settle <= 60.0:
            raise ValueError(f"settle_time must be in [0, 60] s, got {settle}")
        q0 = self.q
        ik = self.ik.solve(T_req, q0, self.rng)
        messages = []
        if not ik.success:
            messages.append(
                f"target unreachable: executed the closest reachable pose, "
                f"{1e3 * ik.position_error:.1f} mm and {np.degrees(ik.rotation_error):.2f} deg away"
            )
        q_goal, collision_message = self._safe_goal(q0, ik.q)
        if collision_message:
            messages.append(collision_message)
        return self._move_joints(T_req, q_goal, settle, on_step, observer, messages)

    def move_joints(
        self,
        q_goal: np.ndarray,
        on_step: StepCallback | None = None,
        settle_time: float | None = None,
        observer: StepObserver | None = None,
    ) -> MotionResult:
        """Move to the joint positions ``q_goal`` (7,) (from ``solve_ik``, checked by ``first_collision``) in
        physics, as ``move_to`` executes its goal; no IK, no collision check."""
        q_goal = np.asarray(q_goal, dtype=float)
        settle = self.cfg.motion.settle_time if settle_time is None else float(settle_time)
        p, R = self.ik.forward(q_goal)
        return self._move_joints(make_transform(R, p), q_goal, settle, on_step, observer, [])

    def _move_joints(
        self,
        T_req: np.ndarray,
        q_goal: np.ndarray,
        settle: float,
        on_step: StepCallback | None,
        observer: StepObserver | None,
        messages: list[str],
    ) -> MotionResult:
        plan = self._plan(self.q, q_goal, settle)
        t_start = self.time_ns
        trace = self._execute(plan, on_step, observer)
        return self._result(T_req, q_goal, plan, trace, messages, t_start)

    def _plan(self, q0: np.ndarray, q_goal: np.ndarray, settle: float) -> JointPlan:
        mc, dt = self.cfg.motion, self.model.opt.timestep
        steps = motion_steps(q_goal - q0, self.limits, mc.velocity_scale, mc.acceleration_scale, mc.min_duration, dt)
        hold = self._steps_for(settle)
        return quintic_plan(q0, q_goal, steps, hold, dt)

    def _execute(
        self, plan: JointPlan, on_step: StepCallback | None, observer: StepObserver | None
    ) -> dict[str, np.ndarray]:
        """Run the plan in physics; logs (K + 1, .) arrays of the states at steps 0..K."""
        m, d = self.model, self.data
        ctrl = self._ctrl_table(plan)
        n, t0_ns = plan.num_steps, self.time_ns
        live = [] if observer is None else observer.live_steps(t0_ns, n, self.timestep_ns)
        q_log = np.empty((n + 1, NUM_JOINTS))
        v_log = np.empty((n + 1, NUM_JOINTS))
        q_log[0], v_log[0] = d.qpos, d.qvel
        if on_step is None:
            sensors = self._roll_out(ctrl[:n], live, observer, q_log[1:], v_log[1:])
        else:
            sensors = self._step_by_step(ctrl[:n], live, observer, on_step, q_log[1:], v_log[1:])
        d.ctrl[:] = self._hold_ctrl(plan.q[-1])
        mujoco.mj_forward(m, d)
        sensors = np.vstack([sensors, d.sensordata])  # the state at the end (no step starts there)
        p, R = self._frame(sensors, "ee")
        if observer is not None:
            observer.on_steps(StepPoses(t0_ns, self.timestep_ns, *self._frame(sensors[:n], "imu"), p[:n]))
        return {"q": q_log, "qd": v_log, "p": p, "R": R.reshape(-1, 3, 3)}

    def _step_by_step(
        self,
        ctrl: np.ndarray,
        live: list[int],
        observer: StepObserver | None,
        on_step: StepCallback,
        q_out: np.ndarray,
        v_out: np.ndarray,
    ) -> np.ndarray:
        """Steps one at a time with ``on_step`` after each; (K, nsensordata) sensor values of the steps."""
        m, d = self.model, self.data
        sensors = np.empty((len(ctrl), m.nsensordata))
        live = set(live)
        for k in range(len(ctrl)):
            d.ctrl[:] = ctrl[k]
            mujoco.mj_step(m, d)
            self._step += 1
            # Derived quantities now describe step k (pre-step state); qpos/qvel step k + 1.
            sensors[k], q_out[k], v_out[k] = d.sensordata, d.qpos, d.qvel
            t_ns = (self._step - 1) * self.timestep_ns
            on_step(self, t_ns)
            if k in live:
                observer.on_live_step(self, t_ns)
        return sensors

    def _roll_out(
        self, ctrl: np.ndarray, live: list[int], observer: StepObserver | None, q_out: np.ndarray, v_out: np.ndarray
    ) -> np.ndarray:
        """The steps in MuJoCo's ``rollout``, cut after each live step; (K, nsensordata) sensor values of the steps."""
        m, d = self.model, self.data
        n = len(ctrl)
        state = np.empty((1, n, mujoco.mj_stateSize(m, _STATE)))
        sensors = np.empty((1, n, m.nsensordata))
        control = np.ascontiguousarray(ctrl[None])
        start = np.empty((1, state.shape[2]))
        ends_live = {k + 1 for k in live}
        # On this thread (no pool); made per motion, as it cannot be pickled and a PandaSim can.
        with rollout.Rollout(nthread=0) as runner:
            for first, last in _segments(n, live):
                mujoco.mj_getState(m, d, start[0], _STATE)
                runner.rollout(
                    [m], [d], start, control[:, first:last],
                    nstep=last - first, initial_warmstart=d.qacc_warmstart[None], skip_checks=True,
                    state=state[:, first:last], sensordata=sensors[:, first:last],
                )  # fmt: skip
                self._step += last - first
                if last in ends_live:
                    observer.on_live_step(self, (self._step - 1) * self.timestep_ns)
        qpos = mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_TIME)  # offsets in the state vector
        qvel = qpos + m.nq
        q_out[:] = state[0, :, qpos : qpos + NUM_JOINTS]
        v_out[:] = state[0, :, qvel : qvel + NUM_JOINTS]
        return sensors[0]

    def _frame(self, sensors: np.ndarray, site: str) -> tuple[np.ndarray, np.ndarray]:
        """(K, 3) positions and (K, 9) row-major orientations of ``site`` from sensor rows (K, nsensordata)."""
        pos, x, y, z = (sensors[:, c : c + 3] for c in self._frames[site])
        return np.ascontiguousarray(pos), np.stack([x, y, z], axis=2).reshape(-1, 9)

    def _result(
        self,
        T_req: np.ndarray,
        q_goal: np.ndarray,
        plan: JointPlan,
        trace: dict[str, np.ndarray],
        messages: list[str],
        t_start: int,
    ) -> MotionResult:
        p_goal, R_goal = self.ik.forward(q_goal)
        T_goal = make_transform(R_goal, p_goal)
        lo_margin = np.min(trace["q"] - self.limits.q_min)
        hi_margin = np.min(self.limits.q_max - trace["q"])
        return MotionResult(
            reached=not messages,
            clamped=bool(messages),
            message="; ".join(messages),
            T_requested=T_req,
            T_goal=T_goal,
            T_final=self.ee_pose(),
            q_goal=q_goal,
            duration=plan.move_steps * plan.timestep,
            settle_time=(plan.num_steps - plan.move_steps) * plan.timestep,
            path_length=float(np.sum(np.linalg.norm(np.diff(trace["p"], axis=0), axis=1))),
            rotation_length=rotation_path_length(trace["R"]),
            max_tracking_error=float(np.max(np.abs(trace["q"] - plan.q))),
            position_margin=float(min(lo_margin, hi_margin)),
            velocity_margin=float(np.min(self.limits.v_max - np.abs(trace["qd"]))),
            num_steps=plan.num_steps,
            t_start_ns=t_start,
            t_end_ns=self.time_ns,
        )

    def halt(self) -> None:
        """Command the arm to hold its current joint positions (what a stop does to an interrupted motion)."""
        self.data.ctrl[:] = self._hold_ctrl(self.q)

    def hold(
        self, duration: float, on_step: StepCallback | None = None, observer: StepObserver | None = None
    ) -> MotionResult:
        """Stay at rest at the current joint positions for ``duration`` [s] (physics keeps running)."""
        if not 0.0 <= duration <= 60.0:
            raise ValueError(f"hold duration must be in [0, 60] s, got {duration}")
        q0 = self.q
        dt = self.model.opt.timestep
        plan = quintic_plan(q0, q0, 0, self._steps_for(duration), dt)
        t_start = self.time_ns
        T_now = self.ee_pose()
        trace = self._execute(plan, on_step, observer)
        return self._result(T_now, q0, plan, trace, [], t_start)

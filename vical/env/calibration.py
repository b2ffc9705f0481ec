"""``CalibrationEnv``: the paper's calibration MDP as a gymnasium environment.

One episode: a sensor is drawn from the ``sensor`` distributions, the simulated Panda rests at
its start pose for ``reset_hold`` seconds (first views, still IMU data), then every step moves
the end effector by one action (``vical.env.actions``) inside the workspace around the start
pose, in MuJoCo physics, while the IMU and camera record. The camera frames of the step update
the coverage (``vical.env.coverage``); the state is the coverage plus the current pose offset,
all normalised to [0, 1]. When every coverage term has reached its threshold the episode
terminates and the task's calibrator runs once on the whole recording; its error enters the
terminal reward (``vical.env.rewards``). The step limit truncates the episode.

``info`` carries ``coverage/*`` terms every step and ``calib/*`` results when a calibration ran,
which ``vical-train`` logs to TensorBoard, and ``discount``, the step's factor on the agent's discount
(``reward.path_discount`` to the power of its path; 0 at the step limit when ``step_limit_final``
makes the limit part of the task); ``recording()`` returns the episode's data for
evaluation.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import replace
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from matplotlib.figure import Figure

from vical.calib.detection.aprilgrid import detect_aprilgrid
from vical.calib.detection.checkerboard import detect_checkerboard
from vical.calib.errors import CalibrationError
from vical.calib.tasks import CalibrationTask, run_task
from vical.config_checks import ConfigError, from_mapping
from vical.data import Recording, SensorTruth
from vical.env.actions import goal_offset
from vical.env.information import GROUPS, TASK_GROUPS, Guess, LensSpread
from vical.env.lookahead import ArmTiming, ReachTiming, StepTiming
from vical.env.plots import episode_figure, information_figure
from vical.env.rewards import information_reward_terms, step_reward_terms, terminal_reward_terms
from vical.env.settings import InformationSettings, MdpConfig
from vical.env.state import EpisodeState, env_observation_size
from vical.env.workspace import board_in_sight, check_workspace, pose_frame, sight_range
from vical.geometry import CameraModel
from vical.sim import PandaSim, SimConfig
from vical.sim.hand_held import HandHeldSim
from vical.sim.motion import MotionResult
from vical.sim.person import HandModel
from vical.sim.products import replace_board
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import CameraSampling, Product, SensorSampling, draw_product, sample_sensor
from vical.sim.settings import BoardConfig


def mixed_tasks(task_mix: Mapping[str, Mapping[str, Any]] | None) -> list[CalibrationTask]:
    """The tasks of ``env.task_mix`` (None or empty: none)."""
    if not task_mix:
        return []
    if not isinstance(task_mix, Mapping):
        raise ConfigError(
            f"env.task_mix must map task names to task configs (e.g. /task@env.task_mix.intrinsic: intrinsic "
            f"in the defaults), got {task_mix!r}"
        )
    return [CalibrationTask.from_config(task) for task in task_mix.values()]


def declared_lens_spread(
    settings: InformationSettings, camera: CameraModel, sampling: CameraSampling, task: CalibrationTask
) -> LensSpread | None:
    """The decentred lens the information state considers (``env.information.center_offset_std``; null: the
    sensor distribution's where ``task`` draws decentred lenses) with the distribution's spread of the distortion
    coefficients; None when no offset is declared. ``ConfigError`` where no intrinsics are estimated."""
    std = settings.center_offset_std
    if std is None:  # the distribution's: it decentres pinhole lenses only (vical.sim.sampling.sample_camera)
        std = sampling.center_offset_std if task.asymmetric_distortion and not camera.is_wide_angle else 0.0
    if std == 0:
        return None
    if task.calibrate == "extrinsic" or camera.is_wide_angle:
        raise ConfigError(
            f"env.information.center_offset_std is {std}, but a decentred lens is only considered where a "
            f"pinhole camera's intrinsics are estimated (task {task.name!r}, camera {camera.distortion}); set it to 0"
        )
    tangential = sampling.tangential_std if camera.distortion == "radtan" and task.asymmetric_distortion else 0.0
    coefficient_std = np.array([sampling.k1.std, sampling.k2.std, tangential, tangential])  # equidistant: k3, k4 0
    return LensSpread(std * np.array([camera.width, camera.height], dtype=float), coefficient_std)


class CalibrationEnv(gym.Env):
    """The calibration MDP (``conf/env/calibration.yaml``).

    Args:
        sim: the ``sim`` config group (``vical.sim.SimConfig``).
        sensor: the ``sensor`` config group (``vical.sim.sampling.SensorSampling``).
        task: the ``task`` config group (``vical.calib.tasks.CalibrationTask``).
        task_mix: more tasks by name (each a ``task`` config group): every episode draws its task
            from ``task`` and these with equal probability, so that one policy learns them all.
        hand: None: the Panda moves the sensor; else a simulated person holds it (``vical.sim.person.HandModel``
            settings; ``{}`` its defaults, ``vical-guide``'s person): each step's goal is shown to the person,
            who reaches it with the hand's placement error, lag and tremor (``vical.sim.hand_held.HandHeldSim``).
        **mdp: the MDP constants (``vical.env.settings.MdpConfig``).
    """

    metadata: ClassVar[dict] = {"render_modes": []}

    def __init__(
        self,
        sim: Mapping[str, Any],
        sensor: Mapping[str, Any],
        task: Mapping[str, Any],
        task_mix: Mapping[str, Mapping[str, Any]] | None = None,
        hand: Mapping[str, Any] | None = None,
        **mdp: Any,
    ) -> None:
        self.config = MdpConfig.from_config(mdp)
        self.hand = None if hand is None else from_mapping(HandModel, hand, "env.hand")
        self.tasks = [CalibrationTask.from_config(task), *mixed_tasks(task_mix)]
        self.task = self.tasks[0]
        self.sampling = SensorSampling.from_config(sensor)
        self._sim_config = SimConfig.from_mapping(sim)
        self.recorder: SensorRecorder | None = None
        self._build_scene(self._sim_config.board)
        scale = np.asarray(self.config.action_scale, dtype=np.float32)
        self.action_space = gym.spaces.Box(-scale, scale, dtype=np.float32)
        self.observation_space = gym.spaces.Box(0.0, 1.0, (env_observation_size(self.config),), dtype=np.float32)
        self._bound = self.config.workspace.bound
        self.truth: SensorTruth | None = None
        self.product: Product | None = None  # each reset draws the episode's own
        self._steps = 0

    def _usable(self, product: Product) -> bool:
        """Whether the product's camera (its datasheet) can detect its board from somewhere in the workspace."""
        board = replace_board(self._sim_config.board, product.board)
        near, far = sight_range(board.distance, self.config.workspace)
        return board_in_sight(board.target, product.datasheet.camera, near, far)

    def _build_scene(self, board: BoardConfig) -> None:
        """The simulator, recorder, episode state and pose frame in front of ``board`` (again at a reset whose
        product prints another board: ``sensor.products.boards``)."""
        if self.recorder is not None:
            self.recorder.close()
        sim_config = replace(self._sim_config, board=board)
        if self.hand is None:
            self.sim = PandaSim(sim_config)
        else:  # drawn again at every reset, from the episode's seed
            self.sim = HandHeldSim(sim_config, np.random.default_rng(0), self.hand)
        self.target = board.target
        detector = detect_aprilgrid if self.target.kind == "aprilgrid" else detect_checkerboard
        self.recorder = SensorRecorder(
            self.sim, self.target, self.sampling, detector if self.sampling.backend == "render" else None
        )
        camera = self.sampling.camera
        self.state = EpisodeState(self.config, self.target, (camera.width, camera.height))
        self.frame = pose_frame(self.sim, self.config.workspace)
        if self.hand is None:  # a person's reach is not the arm's: the workspace is where they are sent
            check_workspace(self.sim, self.frame, self.config.workspace)

    # ------------------------------------------------------------------ gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        """Draw a sensor, rest at the start pose for ``reset_hold`` and return the first state.

        ``options={"noise_stream": k}`` (an integer >= 0, default 0) keeps the sensor of ``seed`` but
        draws the IMU and pixel noise from another stream: a second recording of the same sensor.
        """
        super().reset(seed=seed)
        stream = int((options or {}).get("noise_stream", 0))
        if stream < 0:
            raise ValueError(f"options['noise_stream'] must be an integer >= 0, got {stream}")
        sim_seed, sensor_seed, noise_seed = self.np_random.integers(2**63 - 1, size=3)
        if len(self.tasks) > 1:  # drawn after the seeds: a single task's episodes are unchanged
            self.task = self.tasks[int(self.np_random.integers(len(self.tasks)))]
        self.product = draw_product(self.sampling, int(sensor_seed), self._usable)
        board = replace_board(self._sim_config.board, self.product.board)
        if board != self.sim.cfg.board:
            self._build_scene(board)
        self.sim.reset(seed=int(sim_seed))
        self.truth = sample_sensor(
            self.product.sampling, np.random.default_rng(sensor_seed), asymmetric=self.task.asymmetric_distortion
        )
        self.recorder.start(self.truth, np.random.default_rng([int(noise_seed), stream]))
        self.state.reset(self._tracker_task(), self._guess() if self.config.state == "information" else None)
        self._offset = np.zeros(6)
        self._steps = 0
        self._frames_seen = 0
        if self.config.reset_hold > 0:
            self._record(self.sim.hold(self.config.reset_hold, observer=self.recorder), np.zeros(6))
        return self._observation(), self._info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Execute one direct transformation; reward, termination and info as in the module doc."""
        if self.truth is None:
            raise RuntimeError("CalibrationEnv.step called before reset()")
        a = np.clip(np.asarray(action, dtype=float).reshape(-1), self.action_space.low, self.action_space.high)
        before = self.state.coverage.vector()
        excess_before = self.state.excess
        offset_before = self._offset.copy()
        motion = self.sim.move_to(self._goal_pose(a), observer=self.recorder, settle_time=self.config.settle_time)
        self._offset = self._current_offset()
        self._record(motion, self._offset - offset_before)
        self._steps += 1
        if self.config.state == "information":
            terms, terminated = self._information_step(excess_before, motion)
        else:
            terms = step_reward_terms(before, self.state.coverage.vector(), motion, self.config.reward)
            terminated = self.config.terminate_on_coverage and self.state.goal_reached
        truncated = not terminated and self._steps >= self.config.max_steps
        info = self._info()
        info["motion/clamped"] = float(motion.clamped)
        c = self.config
        info["discount"] = self._transition_discount(motion, truncated)
        if (terminated and c.calibrate_on_termination) or (truncated and c.calibrate_on_truncation):
            info.update(self.calibrate_episode())
        if terminated and c.state == "coverage":  # after truncation a calibration is reported, not paid
            terms.update(terminal_reward_terms(info.get("calib/error_pct"), self.config.reward))
        info.update({f"reward/{name}": value for name, value in terms.items()})
        return self._observation(), float(sum(terms.values())), terminated, truncated, info

    def _transition_discount(self, motion: MotionResult, truncated: bool) -> float:
        """The step's factor on the agent's discount: ``path_discount`` per metre; 0 at a final step limit."""
        if truncated and self.config.step_limit_final:
            return 0.0
        return self.config.reward.path_discount ** float(motion.path_length)

    def _information_step(self, excess_before: float, motion: MotionResult) -> tuple[dict[str, float], bool]:
        """Reward terms and termination of the information state (the new frames already added)."""
        terminated = self.config.terminate_on_coverage and self.goal_reached
        terms = information_reward_terms(
            excess_before, self.state.excess, motion.path_length, motion.duration, terminated,
            self.config.information, self.config.reward,
        )  # fmt: skip
        return terms, terminated

    # ------------------------------------------------------------------ episode data
    def recording(self) -> Recording:
        """The episode's recording so far (sensor truth, IMU, frames, trajectory, path length)."""
        return self.recorder.recording({"task": self.task.name, "steps": self._steps})

    def calibrate_episode(self) -> dict[str, float]:
        """Run the task's calibrator on the episode's recording; ``calib/*`` info (error, time, ...)."""
        recording = self.recording()
        start = time.perf_counter()
        try:
            outcome = run_task(self.task, recording)
        except CalibrationError:
            return {"calib/failed": 1.0, "calib/solve_time": time.perf_counter() - start}
        e = outcome.errors
        info = {
            "calib/failed": 0.0,
            "calib/error_pct": outcome.score,
            "calib/intrinsic_pct": e.intrinsic_pct,
            "calib/solve_time": time.perf_counter() - start,
            "calib/frames": float(len(recording.frames)),
            "calib/path_length": recording.path_length,
        }
        for key in ("extrinsic_pct", "rotation_deg", "translation_mm", "time_offset_ms"):
            value = getattr(e, key)
            if value is not None:
                info[f"calib/{key}"] = float(value)
        return info

    @property
    def goal_reached(self) -> bool:
        """The MDP's terminal condition holds: the coverage is complete, or (information state) every group is done."""
        return self.state.goal_reached

    @property
    def step_timing(self) -> StepTiming:
        """How long a step records, as a planner predicts it: the arm's motion or the person's reach, then the
        MDP's ``settle_time``."""
        rest = self.config.settle_time
        return ArmTiming(rest) if self.hand is None else ReachTiming.of(self.hand, rest)

    @property
    def steps(self) -> int:
        """Steps taken in the current episode."""
        return self._steps

    @property
    def pose_offset(self) -> np.ndarray:
        """(6,) current end-effector offset from the start pose: position [m], Euler angles [rad]."""
        return self._offset.copy()

    # ------------------------------------------------------------------ internals
    def _goal_pose(self, action: np.ndarray) -> np.ndarray:
        """World pose of the action's target, clipped to the workspace around the start pose."""
        return self.frame.pose(goal_offset(self._offset, action, self._bound))

    def _current_offset(self) -> np.ndarray:
        return self.frame.offset(self.sim.ee_pose())

    def _record(self, motion: MotionResult, offset_step: np.ndarray) -> None:
        """Account the motion and feed the frames it produced to the state."""
        self.recorder.add_motion(motion)
        self.state.add_motion(offset_step, motion.path_length)
        corners, ids = self.recorder.detections_since(self._frames_seen)
        stamps = self.recorder.stamps_since(self._frames_seen)
        self._frames_seen += len(corners)
        imu = self.recorder.imu_samples() if self.state.information is not None else None
        self.state.add_frames(stamps, corners, ids, imu)

    def _tracker_task(self) -> str:
        """The calibration problem the information state predicts (the task's, ``joint`` for a camera + IMU task)."""
        return self.task.calibrate if self.task.calibrate in TASK_GROUPS else "joint"

    def _guess(self) -> Guess:
        """The information state's linearisation point: the episode's product datasheet (not the truth), with the
        IMU grade it declares.

        In the extrinsic task the intrinsics are given to the calibrator, so they are known here too.
        """
        guess = self.product.datasheet
        camera = self.truth.camera if self.task.calibrate == "extrinsic" else guess.camera
        settings = self.config.information
        return Guess(camera, guess.T_cam_imu, guess.time_offset, guess.imu_noise, settings.pixel_sigma,
                     declared_lens_spread(settings, camera, self.product.sampling.camera, self.task),
                     guess.imu_grade)  # fmt: skip

    def _observation(self) -> np.ndarray:
        return self.state.observation(self._offset, self._steps)

    def _info(self) -> dict[str, float]:
        return self.state.info()

    def trajectory_figure(self, observations: np.ndarray, actions: np.ndarray) -> Figure:
        """TensorBoard's episode figure (``vical.rl.logger`` calls it when the env has it)."""
        if self.config.state == "information":
            return information_figure(observations, self._bound, GROUPS)
        return episode_figure(observations, self._bound)

    def close(self) -> None:
        self.recorder.close()

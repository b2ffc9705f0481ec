"""Run a calibration policy on an arm holding a camera + IMU (``vical.robot``'s interfaces) and record it.

``Collector.run`` does what an episode of ``CalibrationEnv`` does, with a real robot's means:

1. **Alignment** (as in the paper): from live detections (PnP with the sensor's nominal camera) it
   finds the board, then moves the tool to look at the board centre, upright, from ``distance``
   along the board's normal, until it sits there within tolerance. That pose is the episode's
   start pose; the board centre it saw is the workspace's ``look_at``, and the horizontal direction
   toward it the workspace's +x (``PoseFrame``'s ``heading``): the policy's offsets mean what they meant
   in training (+x toward the board, as the simulator's start looks) however the arm's base is turned.
2. **Rest** ``reset_hold`` seconds (still IMU data, first views), then the **policy loop**: the
   policy's action becomes a goal inside the workspace bounds around the start pose (exactly as
   the env clips it), the arm moves there and rests ``settle_time``; the frames and IMU samples
   that arrived update the state with the env's own code (``vical.env.state.EpisodeState``),
   until the policy's stopping rule holds, it is done, or the step or time limit is reached. While
   the policy decides, a live sensor is read on (``decide``): its driver's buffers do not fill.

Everything the sensor delivers after the alignment is written as it arrives
(``vical.io.euroc.EurocStreamWriter``), so a kill leaves a readable, calibratable recording. A
goal the arm refuses is retried as half the step, then pulled toward the workspace's centre, then
skipped; several refused steps in a row, a lost board, an IMU gap, any exception or Ctrl-C stop the arm first; the
recording is flushed and closed in every case.

The path is the sum of the straight lines between the poses the arm reported after each motion
(the arm's own path between them is not streamed); the env measures the simulated path.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from vical.calib.detection import detect_checkerboard
from vical.calib.detection.aprilgrid import detect_aprilgrid, make_aprilgrid_detector
from vical.calib.solve.initialization import pnp
from vical.calib.solve.observations import FrameObservation
from vical.data import NS_PER_S, ImuSamples, Target
from vical.env.actions import goal_offset
from vical.env.information import Guess
from vical.env.lookahead import ArmTiming, StepTiming
from vical.env.reachability import GroupForecast, OutOfReach
from vical.env.settings import MdpConfig
from vical.env.state import EpisodeState
from vical.env.workspace import PoseFrame, look_at_rotation
from vical.geometry import R_CAM_BODY, make_transform, rotation_angle, transform_points
from vical.io.euroc import EurocStreamWriter
from vical.policies.base import Policy
from vical.robot import (
    Arm,
    CameraDetections,
    CameraImage,
    MotionRefused,
    SensorData,
    SensorStreamError,
    StampedPose,
    ViSensor,
)

# The camera's optical frame (z forward, x right, y down) in the tool frame (x forward, y left, z up): the tool
# frame is the camera body's.
R_TOOL_CAMERA = R_CAM_BODY.T


# How far beyond the workspace bounds a reached pose may end ([m] x 3, [rad] x 3) before the run stops:
# tracking error and goals executed a little off stay inside; a wrong tool frame does not.
OUTSIDE_MARGIN = np.r_[0.05, 0.05, 0.05, 0.1, 0.1, 0.1]
# A refused goal offset is retried scaled by these, toward the workspace's centre (the start pose).
CENTRE_FRACTIONS = (0.9, 0.75, 0.5)


class CollectionStopped(RuntimeError):
    """The collection ended early for a reason the user can act on (the arm is stopped, the recording closed)."""


@dataclass(frozen=True)
class Alignment:
    """How the runner brings the board centre to the image centre before the policy starts.

    Attributes:
        distance: [m] from the camera to the board centre at the start pose (the policy's training start).
        tolerance_m: [m] and tolerance_deg: [deg]: close enough to the aligned pose.
        max_moves: alignment motions before giving up.
        max_move: [m] the farthest single alignment motion (beyond: the board is not where it should be).
        min_corners: detected corners a frame needs to locate the board.
        T_tool_camera: (4, 4) the camera's optical frame in the tool frame (nominal; the calibration
            does not use it).
    """

    distance: float
    tolerance_m: float = 0.005
    tolerance_deg: float = 1.0
    max_moves: int = 5
    max_move: float = 0.3
    min_corners: int = 12
    T_tool_camera: np.ndarray = field(default_factory=lambda: make_transform(R_TOOL_CAMERA, np.zeros(3)))

    def __post_init__(self) -> None:
        for name in ("distance", "tolerance_m", "tolerance_deg", "max_move"):
            if not float(getattr(self, name)) > 0:
                raise ValueError(f"collect.align.{name} must be > 0, got {getattr(self, name)}")
        if int(self.max_moves) < 1 or int(self.min_corners) < 4:
            raise ValueError("collect.align.max_moves must be >= 1 and collect.align.min_corners >= 4")
        object.__setattr__(self, "T_tool_camera", np.asarray(self.T_tool_camera, dtype=float).reshape(4, 4))


@dataclass(frozen=True)
class Limits:
    """When the runner stops on its own.

    Attributes:
        max_steps: policy steps (None: the MDP's ``max_steps``).
        time_limit: [s] wall time of the whole collection.
        horizon_s: [s] of recording within which the tolerances must be reached: the run stops there, or as soon as
            the information state's forecast calls a group out of reach within it (``vical.env.reachability``);
            None: no horizon.
        lost_frames: consecutive frames without the board that stop the run.
        max_refused: consecutive steps the arm refuses (with their fallbacks) that stop the run.
        max_imu_gap: [s] the longest gap between IMU samples that is not a broken stream.
        wait_timeout: [s] wall time to wait for sensor data before the stream counts as broken.
        poll_interval: [s] from one read to the next while waiting (at least).
    """

    max_steps: int | None = None
    time_limit: float = 900.0
    horizon_s: float | None = 45.0
    lost_frames: int = 60
    max_refused: int = 3
    max_imu_gap: float = 0.1
    wait_timeout: float = 5.0
    poll_interval: float = 0.005

    def __post_init__(self) -> None:
        if self.max_steps is not None and int(self.max_steps) < 1:
            raise ValueError(f"limits.max_steps must be >= 1 or null, got {self.max_steps}")
        for name in ("time_limit", "max_imu_gap", "wait_timeout"):
            if not float(getattr(self, name)) > 0:
                raise ValueError(f"limits.{name} must be > 0, got {getattr(self, name)}")
        if self.horizon_s is not None and not float(self.horizon_s) > 0:
            raise ValueError(f"limits.horizon_s must be > 0 [s of recording] or null, got {self.horizon_s}")
        if int(self.lost_frames) < 1 or int(self.max_refused) < 1 or float(self.poll_interval) < 0:
            raise ValueError("limits.lost_frames and limits.max_refused must be >= 1, limits.poll_interval >= 0")


@dataclass(frozen=True)
class CollectResult:
    """What a collection did: steps, path [m], sensor time [s], frames, why it ended, the policy's total time
    choosing its actions [s] (wall time: what the arm or the person waited), the verdict of a run stopped as out of
    reach and each goal group's forecast at the end (``vical.env.reachability``)."""

    steps: int
    path_length: float
    duration: float
    frames: int
    goal_reached: bool
    reason: str
    decision_s: float = 0.0
    out_of_reach: OutOfReach | None = None
    forecast: dict[str, GroupForecast] = field(default_factory=dict)


class RobotEpisode:
    """What a policy reads of its episode, off the env: ``config``, ``action_space``, ``pose_offset``, ``steps``, the
    episode's ``state`` and workspace ``frame`` (a planner predicts from them; set when the episode starts), its
    ``step_timing`` (an arm's motion, then the MDP's ``settle_time``; the guide sets a person's reach) and
    ``decision_s``, the policy's wall time choosing its actions so far [s] (``run_policy``)."""

    def __init__(self, config: MdpConfig) -> None:
        self.config = config
        self.step_timing: StepTiming = ArmTiming(config.settle_time)
        scale = np.asarray(config.action_scale, dtype=np.float32)
        self.action_space = gym.spaces.Box(-scale, scale, dtype=np.float32)
        self.pose_offset = np.zeros(6)
        self.steps = 0
        self.decision_s = 0.0
        self.state: EpisodeState | None = None
        self.frame: PoseFrame | None = None


class SensorStream:
    """Reads the sensor, checks the streams, detects the board and (once recording, with a writer) writes everything.

    Keeps the recording's IMU samples for the state (the detections go to the caller).
    """

    def __init__(self, sensor: ViSensor, target: Target, writer: EurocStreamWriter | None, limits: Limits) -> None:
        self.sensor = sensor
        self.target = target
        self.writer = writer
        self.limits = limits
        self.recording = False
        self.keep_imu = False  # keep the IMU samples without recording (the dry run)
        # Shown every frame with its detections as it is read (vical-guide's page), when set.
        self.viewer: Callable[[CameraImage | CameraDetections, np.ndarray, np.ndarray], None] | None = None
        self.frames = 0  # recorded
        self._imu: list[ImuSamples] = []
        self._last_imu: int | None = None
        self._last_frame: int | None = None
        self._lost = 0
        self._aprilgrid = make_aprilgrid_detector() if target.kind == "aprilgrid" else None

    def corners_of(self, frame: CameraImage | CameraDetections) -> tuple[np.ndarray, np.ndarray]:
        """The board's corners (K, 2) and ids (K,) in a frame: detected in its image, or as the sensor found them."""
        if isinstance(frame, CameraDetections):
            return frame.corners, frame.ids
        return self.detect(frame.image)

    def detect(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._aprilgrid is not None:
            return detect_aprilgrid(image, self.target, detector=self._aprilgrid)
        return detect_checkerboard(image, self.target)

    def read(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """New frames' ``(stamp, corners, ids)``; the IMU samples go to the recording."""
        data = self.sensor.read()
        self._check(data)
        detections = []
        for frame in data.frames:
            corners, ids = self.corners_of(frame)
            self._lost = 0 if len(ids) else self._lost + 1
            if self.viewer is not None:
                self.viewer(frame, corners, ids)
            if self.recording:
                if self.writer is not None:
                    self._write(frame, corners, ids)
                self.frames += 1
            detections.append((frame.t_ns, corners, ids))
        if self.recording and self.writer is not None and len(data.imu):
            self.writer.add_imu(data.imu)
        if (self.recording or self.keep_imu) and len(data.imu):
            self._imu.append(data.imu)
        if self._lost >= self.limits.lost_frames:
            raise CollectionStopped(
                f"the board was out of view for {self._lost} frames in a row; check the lighting and the "
                "board's position, then start again"
            )
        return detections

    def _write(self, frame: CameraImage | CameraDetections, corners: np.ndarray, ids: np.ndarray) -> None:
        if isinstance(frame, CameraDetections):
            raise SensorStreamError(
                "the sensor delivers the board's corners without images, and a EuRoC recording needs the images; "
                "record without writing (a corner-level simulation), or use a sensor that streams images"
            )
        self.writer.add_frame(frame.t_ns, frame.image, corners, ids)

    def _check(self, data: SensorData) -> None:
        """Refuse stamps going backwards and gaps in the IMU stream (a broken USB link, a dropped driver)."""
        if len(data.imu):
            t = np.r_[[] if self._last_imu is None else [self._last_imu], data.imu.t].astype(np.int64)
            steps = np.diff(t) / NS_PER_S
            if np.any(steps <= 0):
                raise SensorStreamError("the IMU stamps go backwards; check the sensor's clock settings")
            if len(steps) and steps.max() > self.limits.max_imu_gap:
                k = int(np.argmax(steps))
                raise SensorStreamError(
                    f"the IMU stream has a {steps[k]:.2f} s gap (limit {self.limits.max_imu_gap} s) at "
                    f"{t[k]} ns; check the connection and the driver's IMU rate"
                )
            self._last_imu = int(data.imu.t[-1])
        for frame in data.frames:
            if self._last_frame is not None and frame.t_ns <= self._last_frame:
                raise SensorStreamError("the camera stamps go backwards; check the sensor's clock settings")
            self._last_frame = frame.t_ns

    def start_recording(self) -> None:
        """Write and keep everything from now on (IMU samples kept before, without recording, are dropped)."""
        self.recording, self.keep_imu, self._imu = True, False, []

    def imu(self) -> ImuSamples:
        """All IMU samples of the recording so far."""
        if len(self._imu) != 1:
            self._imu = [ImuSamples.concatenate(self._imu)]
        return self._imu[0]

    @property
    def last_imu_ns(self) -> int | None:
        return self._last_imu

    def last_stamps(self) -> tuple[int | None, int | None]:
        """The last IMU sample's and camera frame's stamps [ns] read so far (None: none yet)."""
        return self._last_imu, self._last_frame


def run_policy(
    policy: Policy,
    episode: RobotEpisode,
    limits: Limits,
    step: Callable[[np.ndarray], None],
    over_time: Callable[[], bool],
    wait: Callable[[Callable[[], bool]], None] | None = None,
) -> tuple[str, OutOfReach | None]:
    """The policy loop of an episode off the env (the arm's and the guided person's): act, ``step``, until the policy's
    last waypoint, its stopping rule, the forecast's out-of-reach verdict or the horizon (``limits.horizon_s``), the
    step limit or ``over_time()``; why it stopped, and the verdict when it was one. With ``wait``, each action is
    decided while ``wait`` runs (``decide``)."""
    state, mdp = episode.state, episode.config
    max_steps = limits.max_steps or policy.max_steps or mdp.max_steps
    judged = policy.stop_at_coverage and state.reach is not None  # a policy that stops at the goal gives up too
    while episode.steps < max_steps:
        deciding = time.perf_counter()
        action = decide(policy, state.observation(episode.pose_offset, episode.steps), episode, wait)
        episode.decision_s += time.perf_counter() - deciding
        if policy.finished:
            return "the policy's last waypoint", None
        step(action)
        if policy.stop_at_coverage and state.goal_reached:
            return "the goal (" + ("every parameter group within tolerance" if mdp.state == "information"
                                   else "coverage complete") + ")", None  # fmt: skip
        verdict = state.reach.verdict(limits.horizon_s) if judged else None
        if verdict is not None:
            return f"out of reach: {verdict.line()}", verdict
        if limits.horizon_s is not None and state.recording_s >= limits.horizon_s:
            return f"the horizon ({limits.horizon_s:g} s of recording)", None
        if over_time():
            return f"the time limit ({limits.time_limit:.0f} s)", None
    return f"the step limit ({max_steps})", None


def decide(
    policy: Policy, observation: np.ndarray, episode: RobotEpisode, wait: Callable[[Callable[[], bool]], None] | None
) -> np.ndarray:
    """The policy's action for ``observation``. With ``wait``, the policy decides in a worker thread while ``wait``
    gets a ``decided()`` to run until (reading a live sensor, whose frames the page shows and whose driver buffers
    would fill); what ``wait`` raises (a lost stream, Ctrl-C) ends the loop once the decision is over. The policy
    reads the episode's state, which nothing updates while it decides: ``wait`` only keeps what it reads."""
    if wait is None:
        return policy.act(observation, episode)
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="vical-decide") as worker:
        decision = worker.submit(policy.act, observation, episode)
        wait(decision.done)
        return decision.result()


def read_until(
    stream: SensorStream, done: Callable[[], bool], take: Callable[[list], None], pause: float | None = None
) -> None:
    """Read ``stream`` (handing the detections to ``take``) until ``done()``, a read every ``pause`` [s] at most (None:
    ``limits.poll_interval``); ``SensorStreamError`` naming the stream when the IMU or the camera delivers nothing for
    ``limits.wait_timeout``."""
    limits = stream.limits
    heard = dict.fromkeys(STREAMS, time.monotonic())
    while not done():
        before, started = stream.last_stamps(), time.monotonic()
        take(stream.read())
        now = time.monotonic()
        for name, was, is_ in zip(STREAMS, before, stream.last_stamps(), strict=True):
            if is_ != was:
                heard[name] = now
        silent = tuple(name for name in STREAMS if now - heard[name] > limits.wait_timeout)
        if silent:
            raise SensorStreamError(SILENT[silent].format(limits.wait_timeout))
        time.sleep(max(0.0, (limits.poll_interval if pause is None else pause) - (time.monotonic() - started)))


STREAMS = ("imu", "camera")  # the order of ``SensorStream.last_stamps``
# What to check when streams are silent (``read_until``).
SILENT = {
    ("imu",): "no IMU samples for {:.0f} s while the camera streams (limits.wait_timeout); check that the sensor's "
    "IMU is enabled and publishes (RealSense: a model with an IMU; ROS: the IMU topic)",
    ("camera",): "no camera images for {:.0f} s while the IMU streams (limits.wait_timeout); check that the sensor's "
    "camera is enabled and publishes (ROS: the image topic)",
    ("imu", "camera"): "no sensor data for {:.0f} s (limits.wait_timeout); check that the camera and the IMU stream",
}


class LiveEpisode:
    """What a policy's episode on a live sensor keeps and how it reads, the arm's (``Collector``) and the guided
    person's (``vical.collection.guide.Guide``): the sensor stream, the state it feeds, the episode the policy sees.

    Args:
        sensor: the live sensor.
        policy: the calibration policy (it sees a ``RobotEpisode`` as its env).
        mdp: the MDP the policy runs in (state, workspace, action scale, step limit, rests).
        task: ``intrinsic``, ``extrinsic`` or ``joint``: the state's calibration problem.
        target: the board.
        guess: the sensor's nominal values (the information state's linearisation; the camera its poses use).
        writer: where the recording goes (None: nowhere).
        limits: stopping settings.
        progress: prints one line per stage and step.
    """

    def __init__(
        self,
        sensor: ViSensor,
        policy: Policy,
        mdp: MdpConfig,
        task: str,
        target: Target,
        guess: Guess,
        writer: EurocStreamWriter | None,
        limits: Limits | None,
        progress: Callable[[str], None],
    ) -> None:
        self.policy = policy
        self.mdp = mdp
        self.task = task
        self.target = target
        self.guess = guess
        self.limits = limits or Limits()
        self.stream = SensorStream(sensor, target, writer, self.limits)
        self.state = EpisodeState(mdp, target, sensor.image_size)
        self.episode = RobotEpisode(mdp)
        self.progress = progress
        self._pending: list[tuple[int, np.ndarray, np.ndarray]] = []  # detections not yet fed to the state

    def _take(self, detections: list[tuple[int, np.ndarray, np.ndarray]]) -> None:
        """Keep what was read for the state's next update."""
        self._pending.extend(detections)

    def _rest(self, seconds: float) -> None:
        """Take what arrived, then keep reading until the IMU stream has advanced ``seconds`` of sensor time."""
        self._take(self.stream.read())
        start = self.stream.last_imu_ns

        def rested() -> bool:
            nonlocal start
            start = self.stream.last_imu_ns if start is None else start
            return start is not None and self.stream.last_imu_ns - start >= seconds * NS_PER_S

        read_until(self.stream, rested, self._take)

    def _decision_wait(self) -> Callable[[Callable[[], bool]], None] | None:
        """How the policy loop waits while the policy decides (``decide``): reading the sensor, when its data come with
        the wall clock (a driver's buffers would fill) or a viewer shows its live image; None (not reading) for a
        simulated sensor without a viewer, whose clock moves only as it is read: a simulated run then does not depend
        on how fast the machine decides. A simulated sensor with a viewer is read once a camera period: its clock then
        moves as the wall clock does, and the simulated person waits as long as the decision takes."""
        sensor = self.stream.sensor
        if sensor.paced_by_reads and self.stream.viewer is None:
            return None
        pause = 1.0 / sensor.camera_rate_hz if sensor.paced_by_reads else None
        return lambda decided: read_until(self.stream, decided, self._take, pause)

    def _update_state(self) -> None:
        """Feed the frames read since the last update (and all IMU samples) to the state: once per step, as the env."""
        pending, self._pending = self._pending, []
        imu = self.stream.imu() if self.state.information is not None else None
        self.state.add_frames([d[0] for d in pending], [d[1] for d in pending], [d[2] for d in pending], imu)


class Collector(LiveEpisode):
    """One policy-driven collection on an arm with a camera + IMU (module doc).

    Args:
        arm, sensor: the robot (``vical.robot``), connected.
        policy: the calibration policy (it sees a ``RobotEpisode`` as its env).
        mdp: the MDP the policy runs in (state, workspace, action scale, step limit, rests).
        task: ``intrinsic``, ``extrinsic`` or ``joint``: the state's calibration problem.
        target: the board.
        guess: the sensor's nominal values (the information state's linearisation; the alignment's camera).
        writer: where the recording goes (None for ``dry_run`` only).
        align, limits: alignment and stopping settings.
        progress: prints one line per stage and step.
    """

    def __init__(
        self,
        arm: Arm,
        sensor: ViSensor,
        policy: Policy,
        mdp: MdpConfig,
        task: str,
        target: Target,
        guess: Guess,
        writer: EurocStreamWriter | None,
        align: Alignment,
        limits: Limits | None = None,
        progress: Callable[[str], None] = print,
    ) -> None:
        super().__init__(sensor, policy, mdp, task, target, guess, writer, limits, progress)
        self.arm = arm
        self.align_settings = align
        self._started = 0.0
        self._episode_start: int | None = None  # [ns] the IMU's last stamp when the episode began
        self._refused = 0

    # ------------------------------------------------------------------ the run
    def run(self, seed: int = 0) -> CollectResult:
        """Align, rest, run the policy; the arm is stopped and the recording closed however it ends."""
        if self.stream.writer is None:
            raise ValueError("Collector.run needs a writer for the recording")
        self.policy.check(self.episode)  # a policy made for another MDP fails before anything moves
        self._started = time.monotonic()
        self.stream.sensor.start()
        try:
            frame = self.align()
            return self._episode(frame, seed)
        except BaseException:
            self.arm.stop()
            raise
        finally:
            self.stream.sensor.stop()
            self.stream.writer.close()

    def _episode(self, frame: PoseFrame, seed: int) -> CollectResult:
        self.stream.start_recording()
        self.state.reset(self.task, self.guess)
        self._episode_start = self.stream.last_imu_ns
        self._rest(self.mdp.reset_hold)
        self._update_state()
        episode = self.episode
        episode.state, episode.frame = self.state, frame
        self.policy.reset(episode, np.random.default_rng(seed))

        def step(action: np.ndarray) -> None:
            self._step(frame, action)
            self._report()

        reason, verdict = run_policy(self.policy, episode, self.limits, step,
                                     lambda: time.monotonic() - self._started > self.limits.time_limit,
                                     self._decision_wait())  # fmt: skip
        self.arm.stop()
        duration = self._sensor_time()
        self.progress(f"stopped at {reason}: {episode.steps} steps, {self.state.path_length:.2f} m, {duration:.1f} s")
        return CollectResult(episode.steps, self.state.path_length, duration, self.stream.frames,
                             self.state.goal_reached, reason, episode.decision_s, verdict,
                             self.state.forecast(self.limits.horizon_s))  # fmt: skip

    def _step(self, frame: PoseFrame, action: np.ndarray) -> None:
        """Move by one action inside the workspace (as ``CalibrationEnv`` does), rest, update the state."""
        episode = self.episode
        space = episode.action_space
        a = np.clip(np.asarray(action, dtype=float).reshape(-1), space.low, space.high)
        bound = self.mdp.workspace.bound
        goal = goal_offset(episode.pose_offset, a, bound)
        before = self.arm.pose()
        reached = self._move(frame, episode.pose_offset, goal)
        episode.steps += 1
        if reached is None:
            return
        offset = frame.offset(reached.T_base_tool)
        if np.any(np.abs(offset) > bound + OUTSIDE_MARGIN):
            raise CollectionStopped(
                f"the arm ended outside the workspace (offset {np.round(offset, 3).tolist()}, bounds "
                f"{np.round(bound, 3).tolist()}); check its tool frame and calibration"
            )
        self._rest(self.mdp.settle_time)
        self.state.add_motion(offset - episode.pose_offset, float(np.linalg.norm(reached.position - before.position)))
        self._update_state()
        episode.pose_offset = offset

    def _move(self, frame: PoseFrame, start: np.ndarray, goal: np.ndarray) -> StampedPose | None:
        """Move toward the workspace offset ``goal``; None when the arm refused it and every fallback.

        The env executes the closest reachable pose of an unreachable goal; an arm refuses it. The
        runner then tries half the step, then the goal pulled toward the workspace's centre (the start
        pose, which the arm reached): near the workspace's edge the part of the box the arm reaches
        depends on where the alignment put the start. A step with every fallback refused is skipped;
        ``limits.max_refused`` of them in a row stop the run.
        """
        fallbacks = [start + 0.5 * (goal - start), *(f * goal for f in CENTRE_FRACTIONS)]
        for k, offset in enumerate([goal, *fallbacks]):
            try:
                reached = self.arm.move_to(frame.pose(offset))
                self._refused = 0
                return reached
            except MotionRefused as err:
                refused = err
                if k == 0:
                    self.progress(f"the arm refused the step ({err}); trying shorter ones")
        self._refused += 1
        if self._refused >= self.limits.max_refused:
            raise MotionRefused(f"{refused}; {self._refused} steps in a row were refused, with their fallbacks")
        return None

    def _sensor_time(self) -> float:
        """[s] of sensor (IMU) time since the episode began: the clock of the summary and ``collect.yaml``."""
        first, last = self._episode_start, self.stream.last_imu_ns
        return 0.0 if first is None or last is None else (last - first) / NS_PER_S

    def _report(self) -> None:
        """A step's line: what the goal still needs (its groups only, as ``goal_reached`` judges them), the data,
        and the episode's sensor time."""
        s, e = self.state, self.episode
        if self.mdp.state == "information":
            goal = s.goal_ratios
            worst = max(goal, key=goal.get)
            what = f"excess {s.excess:.2f} e-folds, worst {worst} {goal[worst]:.2f}x tolerance{s.reach.outlook()}"
        else:
            what = f"coverage {np.mean(list(s.coverage.progress().values())):.0%} of the way"
        time_s = self._sensor_time()
        self.progress(f"step {e.steps}: {what}, {s.frames} frames, path {s.path_length:.2f} m, {time_s:.1f} s")

    # ------------------------------------------------------------------ data
    def _wait(self, done: Callable[[], bool], take: Callable[[list], None]) -> None:
        read_until(self.stream, done, take)

    # ------------------------------------------------------------------ dry run
    def dry_run(self, seconds: float = 3.0) -> list[str]:
        """Check a new set-up without moving: read the streams for ``seconds`` of sensor time, locate the
        board; lines saying what arrived (also printed). Nothing is written."""
        self.stream.sensor.start()
        try:
            pose = self.arm.pose()
            self.stream.keep_imu = True
            seen: list[tuple[int, np.ndarray, np.ndarray]] = []
            seen.extend(self.stream.read())
            start = self.stream.last_imu_ns
            self._wait(lambda: start is None or self._covered(start, seconds), seen.extend)
        finally:
            self.stream.sensor.stop()
        lines = [self._arm_line(pose), *self._camera_lines(seen), self._imu_line(self.stream.imu())]
        for line in lines:
            self.progress(line)
        return lines

    def _covered(self, start: int, seconds: float) -> bool:
        return self.stream.last_imu_ns - start >= seconds * NS_PER_S

    def _arm_line(self, pose: StampedPose) -> str:
        p, lim = pose.position, self.arm.limits
        return (f"arm: tool at [{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] m; limits {lim.max_speed:g} m/s, "
                f"{lim.max_angular_speed:g} rad/s, {lim.max_acceleration:g} m/s^2")  # fmt: skip

    def _camera_lines(self, seen: list[tuple[int, np.ndarray, np.ndarray]]) -> list[str]:
        stamps = np.array([d[0] for d in seen], dtype=np.int64)
        rate = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / NS_PER_S) if len(stamps) > 1 else 0.0
        with_board = [d for d in seen if len(d[2]) >= self.align_settings.min_corners]
        lines = [f"camera: {len(seen)} frames at {rate:.1f} Hz, the board in {len(with_board)} of them"]
        if with_board:
            _, corners, ids = with_board[-1]
            solved = pnp(self.guess.camera, FrameObservation(-1, 0, corners, ids, self.target.points[ids]))
            if solved is not None:
                distance = np.linalg.norm(transform_points(solved[0], self.target.center[None])[0])
                lines.append(f"board: its centre {distance:.3f} m from the camera (with the nominal camera)")
        return lines

    @staticmethod
    def _imu_line(imu: ImuSamples) -> str:
        if len(imu) < 2:
            return "imu: no samples"
        rate = (len(imu) - 1) / ((imu.t[-1] - imu.t[0]) / NS_PER_S)
        gravity = float(np.linalg.norm(imu.accel.mean(axis=0)))
        spin = float(np.degrees(np.linalg.norm(imu.gyro.mean(axis=0))))
        return (f"imu: {len(imu)} samples at {rate:.0f} Hz; at rest it reads {gravity:.2f} m/s^2 (gravity: 9.81) "
                f"and turns {spin:.2f} deg/s (the gyro's bias)")  # fmt: skip

    # ------------------------------------------------------------------ alignment
    def align(self) -> PoseFrame:
        """Bring the board centre to the image centre at ``distance``; the start pose's workspace frame."""
        s = self.align_settings
        for move in range(s.max_moves + 1):
            T_base_camera, T_camera_board = self._locate_board()
            T_base_board = T_base_camera @ T_camera_board
            centre = transform_points(T_base_board, self.target.center[None])[0]
            normal = T_base_board[:3, 2] * np.sign(np.dot(T_base_camera[:3, 3] - centre, T_base_board[:3, 2]))
            position = centre + s.distance * normal
            goal = make_transform(look_at_rotation(position, centre), position)
            now = self.arm.pose().T_base_tool
            off_m = float(np.linalg.norm(goal[:3, 3] - now[:3, 3]))
            off_deg = float(np.degrees(rotation_angle(goal[:3, :3].T @ now[:3, :3])))
            if off_m <= s.tolerance_m and off_deg <= s.tolerance_deg:
                self.progress(f"aligned after {move} moves: board centre {s.distance:.2f} m ahead")
                # The workspace's x runs from the start toward the board, whichever way the base stands.
                return PoseFrame(now, self.mdp.workspace.frame, centre, heading=centre - now[:3, 3])
            if off_m > s.max_move:
                raise CollectionStopped(
                    f"the aligned start pose is {off_m:.2f} m from the arm (more than collect.align.max_move = "
                    f"{s.max_move} m); move the arm so that the board is about {s.distance:.2f} m ahead, then run again"
                )
            if move < s.max_moves:
                self.arm.move_to(goal)
        raise CollectionStopped(
            f"the alignment did not settle within {s.max_moves} moves (still {off_m * 1e3:.0f} mm / {off_deg:.1f} deg "
            "away); check collect.align.T_tool_camera and the nominal camera"
        )

    def _locate_board(self) -> tuple[np.ndarray, np.ndarray]:
        """``(T_base_camera, T_camera_board)`` from the next frame that shows enough of the board."""
        found: list[np.ndarray] = []
        points = self.target.points
        self.stream.read()  # frames of the last motion: the pose below is where it ended

        def look(detections: list[tuple[int, np.ndarray, np.ndarray]]) -> None:
            for _, corners, ids in detections:
                if len(ids) >= self.align_settings.min_corners:
                    solved = pnp(self.guess.camera, FrameObservation(-1, 0, corners, ids, points[ids]))
                    if solved is not None:
                        found.append(solved[0])

        self._wait(lambda: bool(found), look)
        T_base_camera = self.arm.pose().T_base_tool @ self.align_settings.T_tool_camera
        return T_base_camera, found[-1]

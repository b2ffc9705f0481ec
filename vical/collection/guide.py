"""Guide a person who holds the sensor, pose by pose, until the calibration is predicted good enough.

``Guide.run`` is ``vical-collect``'s episode (``vical.collection.runner``) with a person in place of the arm. The
guide knows where the sensor is only from the board: each frame's PnP pose with the datasheet camera. Its world is
the board's frame turned upright (z against gravity, which the IMU reads at rest, through the datasheet
extrinsic), so that the workspace's orientations (``vical.env.workspace``: upright, looking at the board centre)
mean for the person what they mean for the arm.

1. **Start**: it finds the board and the way up (``start_rest`` seconds held still), then shows the start pose
   (the board centre ``distance`` ahead, upright, as the runner aligns the arm) and waits until the person holds
   the sensor still (``Arrival``). The workspace frame is anchored at that start pose; where the person actually
   holds the sensor is its offset.
2. **Each step**: the policy's action becomes a goal offset inside the workspace bounds (as the env clips it);
   the person is shown the goal pose (``vical.robot.Person.show``: the pose in the board's frame, an instruction
   in words, each parameter group's predicted error against its tolerance, the time so far) and the guide reads
   the sensor until the person has settled (``Arrival``); the frames and IMU samples update the state with the
   env's own code (``vical.env.state.EpisodeState``); the offset is where the PnP puts the sensor, not the goal.
3. **Stop** when the policy's stopping rule holds (every group predicted within tolerance: "done"), at the step
   limit, the time limit (of recording), when the board is lost (``Limits.lost_frames``) or the person can no longer
   be guided (``Person.gone``: the page's tab closed).

While the policy decides, the guide reads on for a live sensor or a viewer (``LiveEpisode._decision_wait``): the
page's image follows the sensor, and the person, who holds still meanwhile, is recorded.

The path is the sum of the straight lines between the settled poses. Everything the sensor delivers from the
start pose on is written as it arrives when a writer is given (``vical.io.euroc.EurocStreamWriter``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from vical.calib.solve.initialization import pnp
from vical.calib.solve.observations import FrameObservation
from vical.collection.instructions import Wording, instruction
from vical.collection.runner import (
    CollectionStopped,
    CollectResult,
    Limits,
    LiveEpisode,
    read_until,
    run_policy,
)
from vical.config_checks import require_range
from vical.data import NS_PER_S, Target
from vical.env.actions import goal_offset
from vical.env.information import Guess
from vical.env.lookahead import ReachTiming
from vical.env.settings import MdpConfig
from vical.env.workspace import PoseFrame, look_at_rotation
from vical.geometry import T_CAM_BODY, invert_transform, make_transform, rotation_angle
from vical.io.euroc import EurocStreamWriter
from vical.policies.base import Policy
from vical.robot import Guidance, Person, ViSensor

DONE = "done: hold still, the calibration is good enough"
OUT_OF_REACH = "stop: this sensor cannot reach the tolerances in time"


@dataclass(frozen=True)
class Arrival:
    """When the person holds the sensor where they were sent (or has stopped trying).

    Attributes:
        min_s: [s] of recording after a pose is shown before an arrival counts (reading it, starting to move).
        still_s: [s] the window over which the sensor must be still.
        still_m: [m] and still_deg: [deg]: the largest spread of its poses over that window that is still.
        patience_s: [s] after which the guide takes the pose the sensor is in and goes on.
    """

    min_s: float = 1.0
    still_s: float = 0.5
    still_m: float = 0.01
    still_deg: float = 2.0
    patience_s: float = 8.0

    def __post_init__(self) -> None:
        for name in ("min_s", "still_s", "still_m", "still_deg", "patience_s"):
            require_range(f"arrival.{name}", getattr(self, name), 0.0, low_open=True)


@dataclass(frozen=True)
class Start:
    """Where the guide sends the person first (the workspace's start pose) and how it finds the way up.

    Attributes:
        distance: [m] from the camera to the board centre at the start pose (the policy's training start).
        start_rest: [s] of the sensor held still before the start, for gravity's direction.
        min_corners: detected corners a frame needs for its pose.
    """

    distance: float
    start_rest: float = 1.0
    min_corners: int = 8

    def __post_init__(self) -> None:
        require_range("start.distance", self.distance, 0.0, low_open=True)
        require_range("start.start_rest", self.start_rest, 0.0, low_open=True)
        require_range("start.min_corners", self.min_corners, 4)


def upright_board_frame(T_board_cam: np.ndarray, up_board: np.ndarray) -> np.ndarray:
    """``T_world_board`` (4, 4) of the upright world at the board: origin the board's, z up (``up_board`` (3,), in the
    board's frame), x along the board's normal away from the camera ``T_board_cam`` (4, 4) made horizontal (the board's
    x where the board lies flat). The policies' world: the env's camera starts looking along +x at a board that faces
    it, so a position offset or action means here what it means in training (a +x step goes toward the board)."""
    z = np.asarray(up_board, dtype=float) / np.linalg.norm(up_board)
    into_board = np.array([0.0, 0.0, -np.sign(T_board_cam[2, 3]) or -1.0])  # the board's z, from the camera's side
    x = into_board - np.dot(into_board, z) * z
    if np.linalg.norm(x) < 0.1:  # a board lying flat: any horizontal x
        x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    x /= np.linalg.norm(x)
    R_board_world = np.c_[x, np.cross(z, x), z]
    return make_transform(R_board_world.T, np.zeros(3))


class Guide(LiveEpisode):
    """One guided collection with a person holding the sensor (module doc).

    Args:
        sensor: the live sensor (``vical.robot.ViSensor``).
        person: who holds it and is shown the guidance.
        policy: the collection policy (it sees a ``RobotEpisode`` as its env).
        mdp: the MDP the policy runs in (state, workspace, action scale, step limit).
        task: the state's calibration problem (``intrinsic``, ``extrinsic``, ``joint``).
        target: the board.
        guess: the sensor's nominal values (the information state's linearisation, the poses' camera, gravity's
            extrinsic).
        writer: where the recording goes (None: nowhere).
        start, arrival, wording, limits: the guide's settings.
        reach: how long the planners predict a person's step to take (None: the simulated person's reach, then
            the arrival's ``still_s``).
        progress: one line per stage and step (the instructions of a run without a page).

    Attributes:
        T_world_board: (4, 4) the board in the guide's upright world (found at the start).
    """

    def __init__(
        self,
        sensor: ViSensor,
        person: Person,
        policy: Policy,
        mdp: MdpConfig,
        task: str,
        target: Target,
        guess: Guess,
        writer: EurocStreamWriter | None,
        start: Start,
        arrival: Arrival | None = None,
        wording: Wording | None = None,
        limits: Limits | None = None,
        progress: Callable[[str], None] = print,
        reach: ReachTiming | None = None,
    ) -> None:
        super().__init__(sensor, policy, mdp, task, target, guess, writer, limits, progress)
        self.person = person
        self.start = start
        self.arrival = arrival or Arrival()
        self.episode.step_timing = reach or ReachTiming(rest=self.arrival.still_s)
        self.wording = wording or Wording()
        self._poses: list[tuple[int, np.ndarray]] = []  # (stamp, T_world_body) of the frames since the last pose shown
        self._T_cam_board: np.ndarray | None = None  # the latest frame's that posed the board
        self.T_world_board = np.eye(4)
        self._t0: int | None = None

    # ------------------------------------------------------------------ the run
    def run(self, seed: int = 0) -> CollectResult:
        """Start, guide, stop; the sensor is stopped and the recording closed however it ends."""
        self.policy.check(self.episode)
        self.stream.sensor.start()
        try:
            frame = self._start()
            return self._episode(frame, seed)
        finally:
            self.stream.sensor.stop()
            if self.stream.writer is not None:
                self.stream.writer.close()

    def _start(self) -> PoseFrame:
        """Find the board and the way up, show the start pose, wait for the person; the workspace frame."""
        self.stream.keep_imu = True
        self._rest(self.start.start_rest)
        T_board_cam = invert_transform(self._last_pose())
        imu = self.stream.imu()
        accel = imu.accel[len(imu) // 2 :].mean(axis=0)  # the rest's second half: the person has stopped moving
        up_board = T_board_cam[:3, :3] @ self.guess.T_cam_imu[:3, :3] @ accel  # specific force at rest: up
        self.T_world_board = upright_board_frame(T_board_cam, up_board)
        self._poses = []  # posed in the board's frame before the world was known
        centre = (self.T_world_board @ np.r_[self.target.center, 1.0])[:3]
        toward_camera = (self.T_world_board @ T_board_cam)[:3, 3] - centre
        toward_camera[2] = 0.0  # the start looks at the centre horizontally, as the arm's alignment does
        position = centre + self.start.distance * toward_camera / np.linalg.norm(toward_camera)
        T_start = make_transform(look_at_rotation(position, centre), position)
        frame = PoseFrame(T_start, self.mdp.workspace.frame, centre)
        self._show(T_start)
        self._settle()
        self.episode.pose_offset = frame.offset(self._body_now())
        self.stream.start_recording()  # from the start pose on, as the runner records from its aligned pose
        self._t0, self._pending = self.stream.last_imu_ns, []
        self.progress(f"started {self.start.distance:.2f} m before the board")
        return frame

    def _episode(self, frame: PoseFrame, seed: int) -> CollectResult:
        self.state.reset(self.task, self.guess)
        self._rest(self.mdp.reset_hold)
        self._update_state()
        episode = self.episode
        episode.state, episode.frame = self.state, frame
        self.policy.reset(episode, np.random.default_rng(seed))
        reason, verdict = run_policy(self.policy, episode, self.limits, lambda action: self._step(frame, action),
                                     lambda: self._elapsed() > self.limits.time_limit,
                                     self._decision_wait())  # fmt: skip
        if self.state.goal_reached or verdict is not None:
            words = DONE if verdict is None else f"{OUT_OF_REACH}: {verdict.line()}"
            self.person.show(Guidance(None, words, dict(self.state.goal_ratios), self._elapsed(), done=True))
        self.progress(f"stopped at {reason}: {episode.steps} steps, {self.state.path_length:.2f} m, "
                      f"{self._elapsed():.1f} s")  # fmt: skip
        return CollectResult(episode.steps, self.state.path_length, self._elapsed(), self.stream.frames,
                             self.state.goal_reached, reason, episode.decision_s, verdict,
                             self.state.forecast(self.limits.horizon_s))  # fmt: skip

    def _step(self, frame: PoseFrame, action: np.ndarray) -> None:
        """Show the action's goal, wait for the person to settle, update the state with where the sensor is."""
        episode = self.episode
        space = episode.action_space
        a = np.clip(np.asarray(action, dtype=float).reshape(-1), space.low, space.high)
        goal = goal_offset(episode.pose_offset, a, self.mdp.workspace.bound)
        before = self._body_now()
        self._show(frame.pose(goal))
        self._settle()
        after = self._body_now()
        episode.steps += 1
        offset = frame.offset(after)
        self.state.add_motion(offset - episode.pose_offset, float(np.linalg.norm(after[:3, 3] - before[:3, 3])))
        self._update_state()
        episode.pose_offset = offset
        self.progress(f"step {episode.steps}: {self._worst()}, {self.state.frames} frames, {self._elapsed():.1f} s")

    # ------------------------------------------------------------------ the person
    def _show(self, T_world_body: np.ndarray) -> None:
        """Show the person the pose ``T_world_body`` with the instruction from where the sensor is now."""
        T_board_body = invert_transform(self.T_world_board) @ T_world_body
        T_board_cam = invert_transform(self._last_pose())
        words = instruction(T_board_cam, T_board_body @ invert_transform(T_CAM_BODY), self.wording)
        ratios = dict(self.state.goal_ratios) if self.state.information is not None else {}
        self.person.show(Guidance(T_board_body, words, ratios, self._elapsed()))
        self.progress(f"next: {words}")
        self._poses = []

    def _settle(self) -> None:
        """Read until the person holds the sensor still (``Arrival``), or has had ``patience_s``."""
        shown = self.stream.last_imu_ns
        a = self.arrival

        def settled() -> bool:
            waited = (self.stream.last_imu_ns - shown) / NS_PER_S
            return waited >= a.patience_s or (waited >= a.min_s and self._still())

        read_until(self.stream, settled, self._take)

    def _still(self) -> bool:
        """The poses of the last ``still_s`` (all of its frames) spread by less than ``still_m`` and ``still_deg``."""
        if not self._poses:
            return False
        last = self._poses[-1][0]
        window = [T for t, T in self._poses if last - t <= self.arrival.still_s * NS_PER_S]
        if (last - self._poses[0][0]) < self.arrival.still_s * NS_PER_S or len(window) < 2:
            return False
        spread_m = max(float(np.linalg.norm(T[:3, 3] - window[-1][:3, 3])) for T in window)
        spread_deg = max(np.degrees(rotation_angle(T[:3, :3].T @ window[-1][:3, :3])) for T in window)
        return spread_m <= self.arrival.still_m and spread_deg <= self.arrival.still_deg

    # ------------------------------------------------------------------ data
    def _take(self, detections: list[tuple[int, np.ndarray, np.ndarray]]) -> None:
        """Keep the detections for the state and the pose of each frame that shows enough of the board; stop when the
        person can no longer be guided (every read comes here, after the recording has its data)."""
        why = self.person.gone()
        if why is not None:
            raise CollectionStopped(why)
        super()._take(detections)
        for stamp, corners, ids in detections:
            T_cam_board = self._pose(corners, ids)
            if T_cam_board is not None:
                self._T_cam_board = T_cam_board
                self._poses.append((stamp, self._body(T_cam_board)))

    def _pose(self, corners: np.ndarray, ids: np.ndarray) -> np.ndarray | None:
        if len(ids) < self.start.min_corners:
            return None
        solved = pnp(self.guess.camera, FrameObservation(-1, 0, corners, ids, self.target.points[ids]))
        return None if solved is None else solved[0]

    def _body(self, T_cam_board: np.ndarray) -> np.ndarray:
        """``T_world_body`` of the camera that sees the board at ``T_cam_board``."""
        return self.T_world_board @ invert_transform(T_cam_board) @ T_CAM_BODY

    def _last_pose(self) -> np.ndarray:
        """``T_cam_board`` of the latest frame that posed the board."""
        if self._T_cam_board is None and self.stream.last_stamps()[1] is None:  # a camera that sends nothing
            raise CollectionStopped(
                f"no camera images in the first {self.start.start_rest:g} s while the IMU streams; check that the "
                "sensor's camera is enabled and publishes (ROS: the image topic)"
            )
        if self._T_cam_board is None:
            raise CollectionStopped(
                f"the board was not seen in the first {self.start.start_rest:g} s; hold the sensor so that the whole "
                "board is in view, then start again"
            )
        return self._T_cam_board

    def _body_now(self) -> np.ndarray:
        """``T_world_body`` of the latest frame that posed the board."""
        return self._body(self._last_pose())

    def _elapsed(self) -> float:
        """[s] of recording (IMU time) since the start pose was reached (0 before)."""
        last = self.stream.last_imu_ns
        return 0.0 if last is None or self._t0 is None else (last - self._t0) / NS_PER_S

    def _worst(self) -> str:
        goal = self.state.goal_ratios
        if not goal:
            return "no state"
        worst = max(goal, key=goal.get)
        return f"worst {worst} {goal[worst]:.2f}x tolerance{self.state.reach.outlook()}"

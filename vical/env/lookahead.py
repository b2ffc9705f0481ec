"""What a candidate step would add to the information state, predicted from the current estimate (never the truth).

The information-greedy planner (``vical.policies.greedy``) scores candidate actions by the information state
each would leave. For one candidate, from the episode's state as it stands:

- **the motion**: the workspace offset goes along the straight line from the current offset to the action's goal
  (clipped to the workspace, as the env and the collection runner execute it) with the minimum-jerk profile of
  the arm's motions, in the step timing's ``motion_time`` (the arm's, ``ArmTiming``: a least-squares fit of the
  simulated Panda's step durations to the step's translation and rotation, ``DURATION_FIT``; a person's,
  ``ReachTiming``: the hand model's reach), then rests the timing's ``rest``;
- **the views**: the camera poses along it (``PoseFrame.pose`` and the camera's optical frame in the body frame)
  relative to the board where the last frame's PnP pose (with the guessed camera) puts it; the board's corners
  projected with the guessed camera where the detector reports them (the visibility rules of
  ``vical.sim.camera.ProjectBackend``: tags in the image, large enough, not too oblique), one predicted frame
  per ``FRAME_INTERVAL`` standing for the camera frames of its interval;
- **the IMU**: the guessed IMU's (``Guess.T_cam_imu``) rates and specific forces along the same path, noise-free
  at ``IMU_RATE`` (the information depends on them through the factors' Jacobians, not on their noise);
- a fork of the tracker takes these frames as it takes recorded ones; its ratios give the excess after the step.

``Lookahead.following`` predicts on from where a prediction leaves the episode (its offset and its fork of the
information, the board where this lookahead puts it): the two-step planner's second step.

The prediction's errors: the arm's joint-space motion is not the straight offset line, and its duration scatters
around the fit (rms 0.53 s over steps of 0.5-2 s); the board's pose is the last PnP's, with the guessed camera.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from vical.calib.solve.observations import FrameObservation
from vical.config_checks import require_range
from vical.data import ImuSamples
from vical.env.actions import goal_offset
from vical.env.information import InformationTracker
from vical.env.settings import MdpConfig
from vical.env.state import EpisodeState
from vical.env.workspace import PoseFrame
from vical.geometry import T_CAM_BODY, invert_transform
from vical.sim.camera import ProjectBackend
from vical.sim.motion import quintic
from vical.sim.person import HandModel, reach_duration

# [s], [s/m], [s/rad]: a step's motion time from its translation and rotation (norms of the offset's change):
# least squares over 60 random steps of the simulated Panda in the practitioner's workspace (sensor seeds
# 100-103, velocity_scale 0.5), rms 0.53 s over motions of 0.5-2.0 s.
DURATION_FIT = (0.37, 4.0, 0.38)
FRAME_INTERVAL = 0.25  # [s] between predicted frames
IMU_RATE = 100.0  # [Hz] predicted IMU samples
DEFAULT_FRAME_RATE = 10.0  # [Hz] the camera's rate before the state has measured it
GRAVITY_WORLD = np.array([0.0, 0.0, -9.81])  # [m/s^2] the workspace frame's world has z up
T_BODY_CAM = invert_transform(T_CAM_BODY)


@dataclass(frozen=True)
class Prediction:
    """What a candidate step is predicted to do.

    Attributes:
        goal: (6,) the workspace offset it heads for (clipped to the workspace).
        motion_time: [s] the motion (without the rest after it); path_length: [m] the camera's translation.
        views: predicted frames that see the board.
        ratios: each group's predicted error over its tolerance after the step.
        excess: the goal's e-folds left after the step; goal_reached: every goal group within tolerance.
        axes: the extrinsic's axes after the step as the state carries them (``EpisodeState.axes_of``; empty
            without ``env.information.axis_uncertainty``).
        tracker: the fork of the information with the step's predicted frames (``Lookahead.following``).
    """

    goal: np.ndarray
    motion_time: float
    path_length: float
    views: int
    ratios: dict[str, float]
    excess: float
    goal_reached: bool
    axes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tracker: InformationTracker | None = field(default=None, repr=False, compare=False)


def _norms(delta: np.ndarray) -> tuple[float, float]:
    """[m], [rad] the translation and rotation of a change ``delta`` (6,) of the workspace offset."""
    return float(np.linalg.norm(delta[:3])), float(np.linalg.norm(delta[3:]))


@dataclass(frozen=True)
class ArmTiming:
    """How long an arm's step records: the simulated Panda's motion (``DURATION_FIT``), then ``rest`` [s] (the
    MDP's ``settle_time``). The env's and ``vical-collect``'s."""

    rest: float = 0.0

    def motion_time(self, delta: np.ndarray) -> float:
        """[s] the predicted motion time of a step that changes the workspace offset by ``delta`` (6,)."""
        translation, rotation = _norms(delta)
        if translation == 0.0 and rotation == 0.0:
            return 0.0
        base, per_metre, per_radian = DURATION_FIT
        return base + per_metre * translation + per_radian * rotation


@dataclass(frozen=True)
class ReachTiming:
    """How long a person's step records (``vical-guide``, an env with a hand): a minimum-jerk reach of at least
    ``min_s`` [s], slowed so that its peak speed and rate stay within ``max_speed`` [m/s] and ``max_rate`` [deg/s]
    (the simulated person's reach, ``vical.sim.person``; its defaults), then ``rest`` [s] (the guide's wait until
    it sees the sensor held still, an env's ``settle_time``)."""

    min_s: float = HandModel.settle_s
    max_speed: float = HandModel.max_speed
    max_rate: float = HandModel.max_rate
    rest: float = 0.0

    def __post_init__(self) -> None:
        for name in ("min_s", "max_speed", "max_rate"):
            require_range(f"reach.{name}", getattr(self, name), 0.0, low_open=True)
        require_range("reach.rest", self.rest, 0.0)

    @classmethod
    def of(cls, hand: HandModel, rest: float) -> ReachTiming:
        """The reach of the simulated ``hand``, then ``rest`` [s]."""
        return cls(hand.settle_s, hand.max_speed, hand.max_rate, rest)

    def motion_time(self, delta: np.ndarray) -> float:
        """[s] the reach that changes the workspace offset by ``delta`` (6,) (placement error aside)."""
        translation, rotation = _norms(delta)
        if translation == 0.0 and rotation == 0.0:
            return 0.0
        return reach_duration(translation, rotation, self.min_s, self.max_speed, self.max_rate)


StepTiming = ArmTiming | ReachTiming


def imu_readings(T_world_imu: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free gyro (N, 3) [rad/s] and accelerometer (N, 3) [m/s^2] readings of an IMU at the poses ``T_world_imu``
    (N >= 2, 4, 4) sampled every ``dt`` [s]: body rates and the specific force ``R^T (a - g)`` by central differences
    of the rotations and positions (one-sided at the ends; the world's z up)."""
    R, p = T_world_imu[:, :3, :3], T_world_imu[:, :3, 3]
    turn = Rotation.from_matrix(np.einsum("nji,njk->nik", R[:-1], R[1:])).as_rotvec() / dt  # over each interval
    gyro = np.vstack([turn[:1], 0.5 * (turn[:-1] + turn[1:]), turn[-1:]])
    accel_world = np.gradient(np.gradient(p, dt, axis=0), dt, axis=0)
    return gyro, np.einsum("nji,nj->ni", R, accel_world - GRAVITY_WORLD)


class Lookahead:
    """Predictions of candidate steps from one moment of an episode (module doc).

    Args:
        state: the episode's state (``state: information``, with at least one posed frame).
        frame: the workspace frame (offsets to camera body poses).
        offset: (6,) the current workspace offset.
        config: the MDP (workspace bounds, information settings).
        timing: how long a step records (the episode's ``step_timing``: an arm's motion or a person's reach).

    Raises:
        ValueError: the state has no information tracker, or no frame has posed the board yet.
    """

    def __init__(
        self,
        state: EpisodeState,
        frame: PoseFrame,
        offset: np.ndarray,
        config: MdpConfig,
        timing: StepTiming,
    ) -> None:
        tracker = state.information
        if tracker is None or tracker.last_pose is None or (tracker.uses_imu and tracker.last_time is None):
            raise ValueError("a lookahead needs the information state and a frame that posed the board")
        self.state, self.frame, self.config = state, frame, config
        self.timing = timing
        self.tracker = tracker
        self.offset = np.asarray(offset, dtype=float)
        T_world_cam = self.camera_pose(self.offset)
        self.T_world_target = T_world_cam @ invert_transform(tracker.last_pose)
        self.board = ProjectBackend(tracker.target, self.T_world_target, pixel_noise_px=0.0)
        self.rate = state.frame_rate or DEFAULT_FRAME_RATE

    def camera_pose(self, offset: np.ndarray) -> np.ndarray:
        """(4, 4) ``T_world_cam`` (optical frame) at the workspace ``offset`` (6,); (N, 4, 4) at offsets (N, 6)."""
        return self.frame.pose(offset) @ T_BODY_CAM

    def predict(self, action: np.ndarray) -> Prediction:
        """The step of ``action`` (6,) from the current offset, predicted (module doc)."""
        goal = goal_offset(self.offset, action, self.config.workspace.bound)
        delta = goal - self.offset
        moving = self.timing.motion_time(delta)
        total = moving + self.timing.rest
        count = max(1, round(total / FRAME_INTERVAL))
        tracker = self.tracker.fork(frame_weight=max(total / count * self.rate, 1.0))
        times = total * np.arange(1, count + 1) / count

        def offset_at(t: np.ndarray) -> np.ndarray:
            s = quintic(t / moving)[0] if moving > 0 else np.ones_like(t)
            return self.offset + s[:, None] * delta

        frames = self._frames(times, offset_at(times))
        imu = self._imu(total, offset_at) if self.tracker.uses_imu else None
        tracker.add_posed_frames(frames, imu)
        ratios = self.state.ratios_of(tracker)
        goal_ratios = self.state.goal_of(ratios)
        return Prediction(
            goal, moving, float(np.linalg.norm(delta[:3])), len(frames), ratios,
            self.state.excess_of(ratios), all(r <= 1.0 for r in goal_ratios.values()), self.state.axes_of(tracker),
            tracker,
        )  # fmt: skip

    def following(self, prediction: Prediction) -> Lookahead:
        """Predictions from where ``prediction`` (one of this lookahead's) leaves the episode: its goal offset and
        its fork of the information; the board stays where this lookahead puts it (a step that loses the board
        still knows where it is)."""
        after = copy.copy(self)
        after.tracker = prediction.tracker
        after.offset = prediction.goal
        return after

    def _frames(self, times: np.ndarray, offsets: np.ndarray) -> list[tuple[FrameObservation, np.ndarray]]:
        """The predicted frames that see the board, with their poses ``T_cam_target``."""
        t0, t_last = self.tracker.first_stamp or 0, self.tracker.last_time or 0.0
        frames = []
        for t, T_world_cam in zip(times, self.camera_pose(offsets), strict=True):
            uv, ids = self.board.ideal_observation(self.tracker.guess.camera, T_world_cam)
            if len(ids) < self.tracker.min_corners:
                continue
            stamp = t0 + round((t_last + t - self.tracker.guess.time_offset) * 1e9)
            obs = FrameObservation(-1, int(stamp), uv, ids, self.tracker.target.points[ids])
            frames.append((obs, invert_transform(T_world_cam) @ self.T_world_target))
        return frames

    def _imu(self, total: float, offset_at) -> ImuSamples:
        """The guessed IMU's noise-free samples from the last frame's state to the step's end."""
        dt = 1.0 / IMU_RATE
        t = np.arange(0.0, total + 2 * dt, dt)
        T_cam_imu = self.tracker.guess.T_cam_imu
        gyro, specific_force = imu_readings(self.camera_pose(offset_at(t)) @ T_cam_imu, dt)
        t0, t_last = self.tracker.first_stamp, self.tracker.last_time
        stamps = t0 + np.round((t_last + t) * 1e9).astype(np.int64)
        return ImuSamples(stamps, gyro, specific_force)

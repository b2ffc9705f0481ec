"""The MDP's state of one episode, fed with the sensor data as it arrives.

``EpisodeState`` is what ``CalibrationEnv`` and ``vical-collect`` share, so that a policy sees the
same state from the simulator and from a real robot: the coverage of the views and the motion
(``vical.env.coverage``) and, for the information state, the predicted uncertainty of each parameter
group over its tolerance (``vical.env.information``), both computed from the detections and the
IMU samples only (never a ground truth).
"""

from __future__ import annotations

import numpy as np

from vical.calib.solve.observations import FrameObservation
from vical.data import ImuNoise, ImuSamples, Target
from vical.env.coverage import Coverage, view_features
from vical.env.information import (
    GROUPS,
    SCORED_GROUPS,
    Guess,
    InformationTracker,
    axis_ratios,
    excess,
    feature,
    features,
    tolerance_ratios,
)
from vical.env.reachability import GroupForecast, ReachForecast
from vical.env.settings import MdpConfig

RATE_FRAMES = 20  # latest frames whose stamps give the camera's frame rate
COVERAGE_SIZE = 24  # the coverage state: 18 coverage terms and the pose offset
INFORMATION_SIZE = len(GROUPS) + 7  # the information state: a value per group, the pose offset, the step fraction
SENSOR_SIZE = 6  # sensor_features' terms
AXIS_SIZE = 6  # the extrinsic's axes: rotation about x, y, z, translation along x, y, z
BOARD_SCALE = 1.0  # [m] a board's larger side maps to [0, 1] over 0 .. 1 m (printed boards are A4 to A0)
PAPER_IMU = ImuNoise()  # noise densities at 0.5 of the sensor features (the paper's IMU)


def observation_size(state: str, sensor_context: bool = False, axis_uncertainty: bool = False) -> int:
    """The length of the observation of an env with ``env.state`` and ``env.information``'s ``sensor_context`` and
    ``axis_uncertainty``."""
    if state != "information":
        return COVERAGE_SIZE
    return INFORMATION_SIZE + SENSOR_SIZE * int(sensor_context) + AXIS_SIZE * int(axis_uncertainty)


def env_observation_size(config: MdpConfig) -> int:
    """The length of the observation of the MDP ``config`` (``observation_size`` of its settings)."""
    information = config.information
    return observation_size(config.state, information.sensor_context, information.axis_uncertainty)


def sensor_features(target: Target, guess: Guess) -> np.ndarray:
    """(6,) what a user declares of the sensor, each in [0, 1]: the board a checkerboard (1) or an aprilgrid (0),
    the board's larger side over 1 m, the guessed lens's horizontal field of view over pi (measured between the
    rays of the image's left and right edges, so a wide-angle model reads as a pinhole of the same view), a
    wide-angle model (1) or a pinhole (0), and the accelerometer's and gyroscope's noise densities (0.5 at the
    paper's IMU, on the groups' scale: ``feature``)."""
    side = float(np.max(np.ptp(target.points[:, :2], axis=0)))
    camera = guess.camera
    edges = camera.unproject(np.array([[0.0, camera.cy], [float(camera.width), camera.cy]]))
    hfov = float(np.arctan(-edges[0, 0]) + np.arctan(edges[1, 0]))
    if not np.isfinite(hfov):  # an edge behind the lens: a view of 180 deg or more
        hfov = np.pi
    noise = guess.imu_noise
    imu = feature(np.array([noise.accel_noise_density / PAPER_IMU.accel_noise_density,
                            noise.gyro_noise_density / PAPER_IMU.gyro_noise_density]))  # fmt: skip
    board = float(target.kind == "checkerboard")
    return np.r_[np.clip([board, side / BOARD_SCALE, hfov / np.pi, float(camera.is_wide_angle)], 0.0, 1.0), imu]


def workspace_pose(offset: np.ndarray, bound: np.ndarray) -> np.ndarray:
    """(6,) the pose ``offset`` normalised to [0, 1] over the workspace's ``bound`` (the policy's input)."""
    return np.clip((np.asarray(offset, dtype=float) + bound) / (2 * bound), 0.0, 1.0)


class EpisodeState:
    """Coverage and (``state: information``) predicted uncertainty of one episode.

    Args:
        config: the MDP's settings (state kind, workspace, thresholds, information settings).
        target: the calibration target.
        image_size: (width, height) [px] of the camera.
    """

    def __init__(self, config: MdpConfig, target: Target, image_size: tuple[int, int]) -> None:
        self.config = config
        self.target = target
        self.image_size = (int(image_size[0]), int(image_size[1]))
        self.coverage = Coverage(config.workspace, config.thresholds, config.view_novelty)
        self.information: InformationTracker | None = None
        self.reach: ReachForecast | None = None  # the information state's: whether the goal is in reach in time
        self.ratios: dict[str, float] = {}
        self.path_length = 0.0
        self.frames = 0
        self._stamps: list[int] = []
        self._sensor = np.zeros(0)  # the sensor features the observation carries (none without sensor_context)
        self._axes = np.zeros(0)  # the extrinsic's axes the observation carries (none without axis_uncertainty)

    def reset(self, task: str, guess: Guess | None) -> None:
        """Start an episode of ``task`` (``intrinsic``, ``extrinsic``, ``joint``); ``guess`` linearises the
        information state (the sensor's datasheet values, never its truth; unused by the coverage state)."""
        self.coverage.reset()
        self.path_length = 0.0
        self.frames = 0
        self._stamps = []
        self._first_stamp: int | None = None
        self.information = None
        self.reach = None
        self.ratios = {}
        if self.config.state == "information":
            if guess is None:
                raise ValueError("the information state needs a guess of the sensor to linearise at")
            self.information = InformationTracker(task, self.target, guess)
            self._update_ratios()
            tolerances = self.config.information.tolerances
            self.reach = ReachForecast({g: tolerances.of(g) for g in self.goal_ratios}, board_kind=self.target.kind,
                                       imu_graded=self.information.counts_imu_grade)  # fmt: skip
            if self.config.information.sensor_context:
                self._sensor = sensor_features(self.target, guess)

    def add_frames(
        self, stamps: list[int], corners: list[np.ndarray], ids: list[np.ndarray], imu: ImuSamples | None
    ) -> None:
        """Feed new frames (camera stamps [ns], corners (K, 2) [px], point ids (K,)) and all IMU samples so far
        (read by the information state only)."""
        width, height = self.image_size
        for c, i in zip(corners, ids, strict=True):
            view = view_features(c, i, self.target, width, height)
            if view is not None:
                self.coverage.add_view(view)
        self.frames += len(corners)
        self._stamps = (self._stamps + [int(t) for t in stamps])[-RATE_FRAMES:]
        if self._first_stamp is None and stamps:
            self._first_stamp = int(stamps[0])
        if self.information is not None:
            points = self.target.points
            seen = zip(stamps, corners, ids, strict=True)
            self.information.add_frames([FrameObservation(-1, int(t), c, i, points[i]) for t, c, i in seen], imu)
            self._update_ratios()
            if self._stamps:
                self.reach.add(self.recording_s, self.goal_ratios)

    def forecast(self, horizon_s: float | None) -> dict[str, GroupForecast]:
        """Each goal group's reachability forecast now, at ``horizon_s`` (empty: not the information state)."""
        return {} if self.reach is None else self.reach.groups(horizon_s)

    @property
    def recording_s(self) -> float:
        """[s] from the episode's first frame to its latest (the clock of the reachability forecast)."""
        return 0.0 if self._first_stamp is None else (self._stamps[-1] - self._first_stamp) / 1e9

    @property
    def frame_rate(self) -> float | None:
        """[Hz] the camera's frame rate over the latest frames (None before two)."""
        if len(self._stamps) < 2 or self._stamps[-1] <= self._stamps[0]:
            return None
        return (len(self._stamps) - 1) / ((self._stamps[-1] - self._stamps[0]) / 1e9)

    def add_motion(self, offset_step: np.ndarray, path_length: float) -> None:
        """Account a motion: the pose offset it changed (6,) and its path [m]."""
        self.coverage.add_motion(offset_step)
        self.path_length += float(path_length)

    def _update_ratios(self) -> None:
        self.ratios = self.ratios_of(self.information)
        self._axes = self.axes_of(self.information)

    def axes_of(self, tracker: InformationTracker) -> np.ndarray:
        """(6,) the extrinsic's predicted error along each camera axis on the state's scale (0 where the task
        estimates no extrinsic) with ``axis_uncertainty``; else empty."""
        s = self.config.information
        if not s.axis_uncertainty:
            return np.zeros(0)
        sigmas = tracker.axis_sigmas()
        if sigmas is None:
            return np.zeros(AXIS_SIZE)
        return feature(axis_ratios(sigmas, tracker.task, s.tolerances, s.confidence))

    def goal_of(self, ratios: dict[str, float]) -> dict[str, float]:
        """The groups of ``ratios`` (group: predicted error over tolerance) the goal needs
        (``env.information.goal_groups``)."""
        if self.config.information.goal_groups == "all":
            return ratios
        scored = SCORED_GROUPS[self.information.task]
        return {g: r for g, r in ratios.items() if g in scored}

    def excess_of(self, ratios: dict[str, float]) -> float:
        """E-folds the goal's groups of ``ratios`` have to shrink by (capped and floored as the reward counts)."""
        s = self.config.information
        return excess(self.goal_of(ratios), s.excess_cap, s.excess_floor, s.outside_weight)

    def ratios_of(self, tracker: InformationTracker) -> dict[str, float]:
        """Each group's predicted error over its tolerance (at the goal's confidence) from ``tracker``."""
        s = self.config.information
        return tolerance_ratios(tracker.sigmas(), s.tolerances, s.confidence)

    @property
    def goal_ratios(self) -> dict[str, float]:
        """The ratios of the groups the goal needs (``env.information.goal_groups``)."""
        return self.goal_of(self.ratios)

    @property
    def excess(self) -> float:
        """E-folds the goal's predicted errors still have to shrink by (ratios capped and floored as the reward
        counts)."""
        return self.excess_of(self.ratios)

    @property
    def goal_reached(self) -> bool:
        """The coverage is complete, or (information state) every group of the goal is within its tolerance."""
        if self.config.state == "information":
            return all(r <= 1.0 for r in self.goal_ratios.values())
        return self.coverage.complete()

    def observation(self, offset: np.ndarray, steps: int) -> np.ndarray:
        """The policy's input: the state's terms, the pose ``offset`` (6,) normalised and (information state)
        the fraction ``steps / max_steps``."""
        if self.config.state == "information":
            return self.information_observation(self.ratios, offset, steps / self.config.max_steps)
        return np.r_[self.coverage.vector(), workspace_pose(offset, self.config.workspace.bound)].astype(np.float32)

    def information_observation(
        self, ratios: dict[str, float], offset: np.ndarray, fraction: float, axes: np.ndarray | None = None
    ) -> np.ndarray:
        """The information state's observation of ``ratios`` (a prediction's or the state's own) at the pose
        ``offset`` (6,), ``fraction`` of the step limit gone; then the episode's sensor features
        (``env.information.sensor_context``) and the extrinsic's axes (``axis_uncertainty``: ``axes``, a
        prediction's, or the state's own when None)."""
        pose = workspace_pose(offset, self.config.workspace.bound)
        axes = self._axes if axes is None else axes
        return np.r_[features(ratios), pose, fraction, self._sensor, axes].astype(np.float32)

    def info(self) -> dict[str, float]:
        """``coverage/*`` and ``information/*`` terms (TensorBoard, progress lines)."""
        info = {f"coverage/{k}": v for k, v in self.coverage.progress().items()}
        info["coverage/views"] = float(self.coverage.num_views)
        info["coverage/path_length"] = self.path_length
        if self.information is not None:
            info.update({f"information/{g}_ratio": r for g, r in self.ratios.items()})
            info["information/excess"] = self.excess
        return info

"""Settings of the calibration MDP (``conf/env/calibration.yaml``), validated at start-up.

Units: m, rad, s; coverage terms are normalised to [0, 1] (``vical.env.coverage``). The defaults are the
values the YAML states: ``conf/env/calibration.yaml``'s, the information state's ``conf/env/information.yaml``'s,
the workspace's and action scale's ``conf/workspace/paper.yaml``'s (``tests/test_config_defaults.py``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vical.config_checks import from_mapping, require, require_range


def _vector(key: str, value: Sequence[float], size: int, positive: bool = True) -> tuple[float, ...]:
    """``value`` as a tuple of ``size`` finite numbers (> 0 when ``positive``); ConfigError naming ``key``."""
    try:
        array = np.asarray(list(value), dtype=float)
    except (TypeError, ValueError):
        array = np.zeros(0)
    ok = array.shape == (size,) and bool(np.all(np.isfinite(array))) and (not positive or bool(np.all(array > 0)))
    require(ok, key, f"{size} finite numbers{' > 0' if positive else ''}", value)
    return tuple(float(v) for v in array)


FRAMES = ("start", "board")


@dataclass(frozen=True)
class Workspace:
    """Bounds of the end-effector (camera body) offset from the episode's start pose.

    An offset ``[x, y, z, roll, pitch, yaw]`` is a position change along world x, y, z from the
    start position and Euler angles (``R = Rz(yaw) Ry(pitch) Rx(roll)``, roll about the camera's
    optical axis) relative to a reference orientation that ``frame`` names:

    - ``start``: the start orientation (the authors' workspace: the camera turns with the offsets
      and loses the board beyond a few degrees);
    - ``board``: the orientation looking from the camera's current position at the board centre,
      upright (``vical.env.workspace``): the zero offset keeps the board centred from anywhere,
      pitch and yaw move it across the image, roll turns it about the optical axis.

    Attributes:
        name: the workspace's name (``conf/workspace/<name>.yaml``), recorded with trained policies.
        frame: ``start`` or ``board``, see above.
        position: (3,) [m] +- bound of the position offset along world x, y, z.
        orientation: (3,) [rad] +- bound of roll, pitch, yaw (pitch < pi/2, where Euler angles are
            singular; roll and yaw <= pi).
    """

    name: str = "paper"
    frame: str = "start"
    position: tuple[float, ...] = (0.08, 0.10, 0.08)
    orientation: tuple[float, ...] = (0.17, 0.15, 0.12)

    def __post_init__(self) -> None:
        require(isinstance(self.name, str) and bool(self.name), "env.workspace.name", "a non-empty string", self.name)
        require(self.frame in FRAMES, "env.workspace.frame", f"one of {FRAMES}", self.frame)
        object.__setattr__(self, "position", _vector("env.workspace.position", self.position, 3))
        object.__setattr__(self, "orientation", _vector("env.workspace.orientation", self.orientation, 3))
        roll, pitch, yaw = self.orientation
        require(pitch < np.pi / 2, "env.workspace.orientation (pitch)", "a bound < pi/2 rad", pitch)
        require(max(roll, yaw) <= np.pi, "env.workspace.orientation (roll, yaw)", "bounds <= pi rad", [roll, yaw])

    @property
    def bound(self) -> np.ndarray:
        """(6,) +- bounds ``[x, y, z [m], roll, pitch, yaw [rad]]`` of the pose offset."""
        return np.array([*self.position, *self.orientation])


@dataclass(frozen=True)
class Thresholds:
    """Coverage each term must reach for the terminal condition (normalised terms).

    Attributes:
        polygon_low, polygon_high: every polygon vertex must lie beyond these image fractions
            (V1 left of and above ``polygon_low``, V3 right of and below ``polygon_high``, ...).
        area_range: ``A_max - A_min`` of the board's image-area fraction.
        skew_range: ``eta_max - eta_min`` of the normalised board-edge angle.
        motion: every component of ``dp_max`` and ``dTheta_max`` (normalised).
    """

    polygon_low: float = 0.45
    polygon_high: float = 0.55
    area_range: float = 0.015
    skew_range: float = 0.05
    motion: float = 0.3

    def __post_init__(self) -> None:
        require_range("env.thresholds.polygon_low", self.polygon_low, 0.0, 0.5, high_open=True)
        require_range("env.thresholds.polygon_high", self.polygon_high, 0.5, 1.0, low_open=True)
        for name in ("area_range", "skew_range", "motion"):
            require_range(f"env.thresholds.{name}", getattr(self, name), 0.0, 1.0, low_open=True)


@dataclass(frozen=True)
class RewardWeights:
    """Reward weights (``vical.env.rewards``).

    Attributes:
        coverage_weight: multiplies the L1 gain of the 18 coverage terms.
        path_weight: c1 [1/m], multiplies the executed end-effector path length of the step.
        rotation_weight: c2 [1/rad], multiplies the executed rotation angle of the step.
        terminal_bonus: c3, paid when the terminal condition is reached.
        accuracy_weight: c4, multiplies ``min(1, floor / error)`` of the terminal calibration.
        accuracy_error_floor: [%] errors at or below this earn the whole accuracy reward.
        path_discount: [per metre] the discount of a metre of path: a step's transition is discounted by
            ``path_discount ** path`` on top of ``agent.gamma`` (reported as ``info["discount"]``), so
            what is gained after a long path counts less, as the comparison at equal path counts it;
            1 (the default): steps are discounted alike.
    """

    coverage_weight: float = 100.0
    path_weight: float = 20.0
    rotation_weight: float = 0.0
    terminal_bonus: float = 100.0
    accuracy_weight: float = 100.0
    accuracy_error_floor: float = 0.1
    path_discount: float = 1.0

    def __post_init__(self) -> None:
        for name in ("coverage_weight", "path_weight", "rotation_weight", "terminal_bonus", "accuracy_weight"):
            require_range(f"env.reward.{name}", getattr(self, name), 0.0)
        require_range("env.reward.accuracy_error_floor", self.accuracy_error_floor, 0.0, low_open=True)
        require_range("env.reward.path_discount", self.path_discount, 0.0, 1.0, low_open=True)


STATES = ("coverage", "information")
GOAL_GROUPS = ("all", "scored")


@dataclass(frozen=True)
class Tolerances:
    """What "good enough" means per parameter group (``state: information``): the error norm each may keep.

    Attributes:
        focal_px, principal_point_px: [px] norm of the (fx, fy) and of the (cx, cy) error.
        distortion_px: [px] displacement error at the image corner.
        rotation_deg, translation_mm: [deg], [mm] norm of the extrinsic rotation / translation error.
        time_offset_ms: [ms] time-offset error.
    """

    focal_px: float = 0.35
    principal_point_px: float = 0.35
    distortion_px: float = 0.5
    rotation_deg: float = 0.1
    translation_mm: float = 2.0
    time_offset_ms: float = 0.1

    def __post_init__(self) -> None:
        for name in GROUP_TOLERANCE:
            value = getattr(self, GROUP_TOLERANCE[name])
            ok = isinstance(value, int | float) and np.isfinite(value) and value > 0
            require(ok, f"env.information.tolerances.{GROUP_TOLERANCE[name]}", "a number > 0", value)

    def of(self, group: str) -> float:
        return float(getattr(self, GROUP_TOLERANCE[group]))


GROUP_TOLERANCE = {
    "focal": "focal_px",
    "principal_point": "principal_point_px",
    "distortion": "distortion_px",
    "rotation": "rotation_deg",
    "translation": "translation_mm",
    "time_offset": "time_offset_ms",
}


@dataclass(frozen=True)
class InformationSettings:
    """The information state (``vical.env.information``) and its stopping rule.

    Attributes:
        tolerances: the error each group may keep (``Tolerances``).
        confidence: the probability with which a stopped episode's errors should all be within
            their tolerances: a group is done when its predicted error quantile (the 1-sigma times
            the chi quantile of the group's dimension, at ``1 - (1 - confidence) / groups``) is
            below its tolerance.
        pixel_sigma: [px] corner noise the frames are weighted with; null measures it from the
            PnP residuals (biased upwards before the lens is known).
        information_weight: reward per e-fold of every group's predicted error above its tolerance.
        excess_cap: a ratio above this counts as this in the reward: how far above its tolerance a
            group starts depends only on the priors' spread (uncapped, the first views paid ~200
            whatever the action).
        excess_floor: a ratio below this counts as this in the reward: 1 pays a group's shrinking down
            to its tolerance; below 1 a group already within tolerance is still paid for shrinking
            while the others are not (the episode still ends when every group is within tolerance).
        outside_weight: an e-fold above a group's tolerance counts this many times one below it (with
            ``excess_floor`` < 1): more than 1 makes finishing the slowest group pay more than refining
            the groups already done.
        time_weight: [1/s] charge per second of the step's motion (the path is charged by
            ``reward.path_weight``).
        center_offset_std: declared 1-sigma of the lens's distortion-centre offset from the principal
            point, in units of the image width (x) and height (y) as ``sensor.camera.center_offset_std``:
            the bias such an offset causes (the pinhole models cannot fit it) is added to the prediction
            (``vical.env.information``); 0 takes the lens model as exact; null declares the sensor
            distribution's where the task draws decentred lenses (``task.asymmetric_distortion``), else 0.
        goal_groups: which groups must be within tolerance to end an episode, and whose shrinking the
            reward pays: ``all`` the task's, or ``scored`` those its evaluation scores (the joint task:
            rotation, translation, time offset; its intrinsics stay in the state). With a decentred
            lens declared, the joint task's intrinsics cannot reach their tolerances.
        sensor_context: the observation also carries what the user declares of the sensor
            (``vical.env.state.sensor_features``: the board's kind and size, the lens's field of view and
            family, the IMU's noise densities), for a policy trained on many sensors' episodes; false
            keeps the information state's 13 numbers (the shipped policies' layout).
        axis_uncertainty: the observation also carries the extrinsic's predicted error along each camera axis
            (rotation about x, y, z, translation along x, y, z, on the groups' scale; 0 where the task estimates no
            extrinsic): which direction the motion has yet to excite, where the groups give the worst axis only.
    """

    tolerances: Tolerances = field(default_factory=Tolerances)
    confidence: float = 0.9
    pixel_sigma: float | None = 0.25
    information_weight: float = 40.0
    excess_cap: float = 10.0
    excess_floor: float = 1.0
    outside_weight: float = 1.0
    time_weight: float = 2.0
    center_offset_std: float | None = 0.0
    goal_groups: str = "all"
    sensor_context: bool = False
    axis_uncertainty: bool = False

    def __post_init__(self) -> None:
        require_range("env.information.confidence", self.confidence, 0.5, 1.0, high_open=True)
        if self.pixel_sigma is not None:
            require_range("env.information.pixel_sigma", self.pixel_sigma, 0.0, low_open=True)
        require_range("env.information.information_weight", self.information_weight, 0.0)
        require_range("env.information.excess_cap", self.excess_cap, 1.0, low_open=True)
        require_range("env.information.excess_floor", self.excess_floor, 0.0, 1.0, low_open=True)
        require_range("env.information.outside_weight", self.outside_weight, 1.0)
        require_range("env.information.time_weight", self.time_weight, 0.0)
        if self.center_offset_std is not None:
            require_range("env.information.center_offset_std", self.center_offset_std, 0.0)
        key = "env.information.goal_groups"
        require(self.goal_groups in GOAL_GROUPS, key, f"one of {GOAL_GROUPS}", self.goal_groups)
        key = "env.information.sensor_context"
        require(isinstance(self.sensor_context, bool), key, "true or false", self.sensor_context)
        key = "env.information.axis_uncertainty"
        require(isinstance(self.axis_uncertainty, bool), key, "true or false", self.axis_uncertainty)


@dataclass(frozen=True)
class MdpConfig:
    """The MDP's constants (everything in ``conf/env/calibration.yaml`` but the sim/sensor/task groups).

    Attributes:
        max_steps: episode step limit (truncation).
        step_limit_final: the step limit is part of the task: its step reports a discount of 0, so an
            agent values nothing past it (the state must carry the step count: ``state: information``).
            False (gymnasium's convention): the limit only truncates, and an agent bootstraps through it,
            as if rewards went on after it.
        action_scale: (6,) bounds of ``[rho, theta, phi, alpha, beta, gamma]``: each action
            component lies in ``[-scale, scale]`` ([m], [rad] x 5).
        workspace: end-effector offset bounds.
        thresholds: terminal-condition thresholds.
        view_novelty: a view enters the coverage set when its L1 distance in
            ``[x, y, area, skew]`` to every stored view exceeds this.
        reward: reward weights.
        reset_hold: [s] the arm rests this long at the start pose when an episode begins,
            recording the first views and still IMU data.
        settle_time: [s] rest after every step's motion.
        calibrate_on_termination: calibrate when the coverage completes and pay the accuracy
            reward (the paper); False skips the solve (an evaluation that calibrates every episode
            itself; the terminal bonus is still paid).
        calibrate_on_truncation: also calibrate when the step limit ends an episode (reported
            in ``info``, not paid); the paper calibrates only at the terminal condition.
        terminate_on_coverage: end the episode (and calibrate) when the coverage is complete;
            False lets fixed trajectories run all their steps (evaluation of baselines).
        state: ``coverage`` (the paper's state, rewards and terminal condition) or
            ``information`` (the predicted calibration uncertainty: ``vical.env.information``;
            terminal when every group is within its tolerance, ``terminate_on_coverage`` then
            switching that condition).
        information: settings of the information state.
    """

    max_steps: int = 20
    step_limit_final: bool = False
    action_scale: tuple[float, ...] = (0.3, 1.57, 1.57, 0.4, 0.4, 0.4)
    workspace: Workspace = field(default_factory=Workspace)
    thresholds: Thresholds = field(default_factory=Thresholds)
    view_novelty: float = 0.1
    reward: RewardWeights = field(default_factory=RewardWeights)
    reset_hold: float = 0.3
    settle_time: float = 0.1
    calibrate_on_termination: bool = True
    calibrate_on_truncation: bool = False
    terminate_on_coverage: bool = True
    state: str = "coverage"
    information: InformationSettings = field(default_factory=InformationSettings)

    def __post_init__(self) -> None:
        require(self.state in STATES, "env.state", f"one of {list(STATES)}", self.state)
        require(
            isinstance(self.max_steps, int) and 1 <= self.max_steps <= 1000,
            "env.max_steps",
            "an integer in [1, 1000]",
            self.max_steps,
        )
        require(
            not self.step_limit_final or self.state == "information",
            "env.step_limit_final",
            "false unless env.state=information (the coverage state does not carry the step count)",
            self.step_limit_final,
        )
        object.__setattr__(self, "action_scale", _vector("env.action_scale", self.action_scale, 6))
        require_range("env.view_novelty", self.view_novelty, 0.0, 4.0)
        require_range("env.reset_hold", self.reset_hold, 0.0, 10.0)
        require_range("env.settle_time", self.settle_time, 0.0, 10.0)

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> MdpConfig:
        return from_mapping(cls, cfg, "env")

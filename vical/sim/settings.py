"""Simulator settings (Hydra group ``sim/``), validated at start-up.

Every value is checked when the dataclass is built; a bad value raises ``vical.config_checks.ConfigError``
naming its dotted key (``sim.physics.timestep``) and the allowed range.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vical.config_checks import ConfigError, from_mapping, require, require_range
from vical.data import NS_PER_S, Target

NUM_JOINTS = 7


def _float_tuple(value: Any, n: int, key: str) -> tuple[float, ...]:
    """``value`` as a tuple of ``n`` finite floats, else a ``ConfigError`` naming ``key``."""
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ConfigError(f"{key} must be a list of {n} numbers, got {value!r}") from None
    require(len(out) == n and all(np.isfinite(out)), key, f"a list of {n} finite numbers", value)
    return out


@dataclass(frozen=True)
class PhysicsConfig:
    """MuJoCo physics.

    Attributes:
        timestep: physics step [s], a whole number of nanoseconds; simulated time is an integer
            count of steps, so timestamps ``step * timestep_ns`` are exact int64 ns.
    """

    timestep: float = 0.001

    def __post_init__(self) -> None:
        require_range("sim.physics.timestep", self.timestep, 0.0, 0.01, low_open=True)
        ns = self.timestep * NS_PER_S
        require(abs(ns - round(ns)) < 1e-6, "sim.physics.timestep", "a whole number of nanoseconds", self.timestep)

    @property
    def timestep_ns(self) -> int:
        """Physics step [ns]."""
        return round(self.timestep * NS_PER_S)

    def steps_per_period(self, rate_hz: float, key: str) -> int:
        """Physics steps per period of a sensor sampling at ``rate_hz`` [Hz].

        Raises ``ConfigError`` naming ``key`` when the sensor period is not a whole number of
        physics steps (samples would not fall on physics states).
        """
        require_range(key, rate_hz, 0.0, 1.0 / self.timestep, low_open=True)
        period_ns = NS_PER_S / rate_hz
        steps = period_ns / self.timestep_ns
        require(
            abs(period_ns - round(period_ns)) < 1e-6 and abs(steps - round(steps)) < 1e-9,
            key,
            f"a rate whose period is a whole multiple of sim.physics.timestep ({self.timestep} s)",
            rate_hz,
        )
        return round(steps)


@dataclass(frozen=True)
class BoardConfig:
    """The calibration target (checkerboard or Kalibr aprilgrid) and where it stands.

    At the robot's start pose (``SimConfig.start``, else the ``home`` keyframe) the board centre
    lies ``distance`` in front of the camera along its
    optical axis (shifted by ``offset``), facing the camera upright as printed (checkerboard: grid
    rows going down the image and columns going right; aprilgrid: tag 0 at the bottom left, board
    x to the right and y up); ``tilt_rpy`` then rotates the board about its centre.

    Attributes:
        kind: ``"checkerboard"`` or ``"aprilgrid"``.
        rows, cols: checkerboard: inner corners (the paper's board: 6 x 7 = 7 x 8 squares);
            aprilgrid: tags (Kalibr's tagRows, tagCols).
        square: checkerboard square side [m]; aprilgrid: tag size [m] (Kalibr's tagSize).
        tag_spacing: aprilgrid only: gap between tags / tag size (Kalibr's tagSpacing).
        border_squares: checkerboard only: white border width [squares] (an aprilgrid carries
            Kalibr's own margin, see ``Target.aprilgrid_image``).
        distance: optical-axis distance from the camera at the start pose to the board centre [m].
        offset: (2,) [m] board centre shift along the camera body's y (left) and z (up) axes.
        tilt_rpy: (3,) [rad] rotation of the board about its centre, Euler [roll, pitch, yaw] in
            the board frame.
        px_per_square: texture resolution [texture px per square, or per tag side: a multiple
            of 10 (the tag's bits) for which the gap is a whole number of pixels].
    """

    kind: str = "checkerboard"
    rows: int = 6
    cols: int = 7
    square: float = 0.07
    border_squares: float = 1.0
    distance: float = 1.5
    offset: tuple[float, float] = (0.0, 0.0)
    tilt_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    px_per_square: int = 100
    tag_spacing: float = 0.3

    def __post_init__(self) -> None:
        require(self.kind in ("checkerboard", "aprilgrid"), "sim.board.kind", "checkerboard or aprilgrid", self.kind)
        if self.kind == "aprilgrid":
            require_range("sim.board.tag_spacing", self.tag_spacing, 0.05, 1.0)
            gap = self.tag_spacing * self.px_per_square
            require(
                self.px_per_square % 10 == 0 and abs(gap - round(gap)) < 1e-6,
                "sim.board.px_per_square",
                "a multiple of 10 for which px_per_square * tag_spacing is whole (aprilgrid texture)",
                self.px_per_square,
            )
        for name in ("rows", "cols", "px_per_square"):
            value = getattr(self, name)
            require(isinstance(value, int) and value >= 2, f"sim.board.{name}", "an integer >= 2", value)
        require_range("sim.board.square", self.square, 0.005, 0.5)
        require_range("sim.board.border_squares", self.border_squares, 0.0, 5.0)
        require_range("sim.board.distance", self.distance, 0.3, 5.0)
        object.__setattr__(self, "offset", _float_tuple(self.offset, 2, "sim.board.offset"))
        object.__setattr__(self, "tilt_rpy", _float_tuple(self.tilt_rpy, 3, "sim.board.tilt_rpy"))
        limit = 0.5 * self.distance
        for axis, value in zip("yz", self.offset, strict=True):
            require_range(f"sim.board.offset ({axis})", value, -limit, limit)
        for axis, value in zip(("roll", "pitch", "yaw"), self.tilt_rpy, strict=True):
            # Beyond ~70 deg the camera sees the board edge-on (or its back).
            require_range(f"sim.board.tilt_rpy ({axis})", value, -1.2, 1.2)

    @property
    def target(self) -> Target:
        """The board's point geometry."""
        if self.kind == "aprilgrid":
            return Target.aprilgrid(self.rows, self.cols, self.square, self.tag_spacing)
        return Target.checkerboard(rows=self.rows, cols=self.cols, square=self.square)


@dataclass(frozen=True)
class MotionConfig:
    """Trajectory planning and joint control.

    Attributes:
        velocity_scale: fraction (0, 1] of the Panda's joint velocity limits a plan may use.
        acceleration_scale: fraction (0, 1] of the joint acceleration limits a plan may use.
        min_duration: shortest motion [s].
        settle_time: default rest at the end of every motion [s] (still data for calibration).
        joint_limit_margin: IK solutions and plans stay this far inside the joint ranges [rad].
        collision_samples: configurations checked for collisions along each planned path.
        feedforward_stride: physics steps between inverse-dynamics evaluations of the plan
            (a cubic spline interpolates the feed-forward torque in between).
        kp: (7,) PD position gains [N m / rad]; kd: (7,) damping gains [N m s / rad].
    """

    velocity_scale: float = 0.5
    acceleration_scale: float = 0.5
    min_duration: float = 0.3
    settle_time: float = 0.0
    joint_limit_margin: float = 0.05
    collision_samples: int = 16
    feedforward_stride: int = 10
    kp: tuple[float, ...] = (1000.0, 1000.0, 1000.0, 1000.0, 400.0, 400.0, 400.0)
    kd: tuple[float, ...] = (50.0, 50.0, 50.0, 50.0, 20.0, 20.0, 20.0)

    def __post_init__(self) -> None:
        require_range("sim.motion.velocity_scale", self.velocity_scale, 0.0, 1.0, low_open=True)
        require_range("sim.motion.acceleration_scale", self.acceleration_scale, 0.0, 1.0, low_open=True)
        require_range("sim.motion.min_duration", self.min_duration, 0.0, 10.0, low_open=True)
        require_range("sim.motion.settle_time", self.settle_time, 0.0, 60.0)
        require_range("sim.motion.joint_limit_margin", self.joint_limit_margin, 0.0, 0.3)
        value = self.collision_samples
        require(
            isinstance(value, int) and 2 <= value <= 1000,
            "sim.motion.collision_samples",
            "an integer in [2, 1000]",
            value,
        )
        value = self.feedforward_stride
        require(
            isinstance(value, int) and 1 <= value <= 100,
            "sim.motion.feedforward_stride",
            "an integer in [1, 100]",
            value,
        )
        for name, high in (("kp", 1e5), ("kd", 1e4)):
            gains = _float_tuple(getattr(self, name), NUM_JOINTS, f"sim.motion.{name}")
            for i, g in enumerate(gains):
                require_range(f"sim.motion.{name}[{i}]", g, 0.0, high, low_open=True)
            object.__setattr__(self, name, gains)


@dataclass(frozen=True)
class IKConfig:
    """Damped-least-squares inverse kinematics.

    Attributes:
        max_iterations: iterations per attempt.
        restarts: extra attempts from seeded random joint configurations when the first fails.
        restart_spread: [rad] restarts start from the first attempt's configuration perturbed by
            ``N(0, restart_spread)`` per joint, so solutions stay on the arm's current branch and a
            small pose step never becomes a swing across the workspace; 0 draws them uniformly over
            the joint ranges (a global search, as the paper's tables were measured).
        damping: Levenberg damping of the least-squares step [m or rad], > 0.
        max_step: largest joint change per iteration [rad].
        position_tolerance: converged below this position error [m].
        rotation_tolerance: converged below this rotation error [rad].
    """

    max_iterations: int = 100
    restarts: int = 10
    restart_spread: float = 0.3
    damping: float = 1e-3
    max_step: float = 0.4
    position_tolerance: float = 1e-5
    rotation_tolerance: float = 1e-5

    def __post_init__(self) -> None:
        for name, high in (("max_iterations", 10_000), ("restarts", 100)):
            value = getattr(self, name)
            require(
                isinstance(value, int) and 0 <= value <= high, f"sim.ik.{name}", f"an integer in [0, {high}]", value
            )
        require(self.max_iterations >= 1, "sim.ik.max_iterations", "an integer in [1, 10000]", self.max_iterations)
        require_range("sim.ik.restart_spread", self.restart_spread, 0.0, 3.0)
        require_range("sim.ik.damping", self.damping, 0.0, 1.0, low_open=True)
        require_range("sim.ik.max_step", self.max_step, 0.0, 3.0, low_open=True)
        require_range("sim.ik.position_tolerance", self.position_tolerance, 0.0, 0.01, low_open=True)
        require_range("sim.ik.rotation_tolerance", self.rotation_tolerance, 0.0, 0.01, low_open=True)


@dataclass(frozen=True)
class StartPose:
    """Where the camera body rests when an episode starts (instead of the ``home`` keyframe).

    The arm reaches it by inverse kinematics from ``home`` when the simulator is built; the board
    is then placed relative to it (``BoardConfig``).

    Attributes:
        position: (3,) [m] camera body origin (the ``ee`` site) in the world.
        rpy: (3,) [rad] its world Euler angles roll, pitch, yaw (``R = Rz(yaw) Ry(pitch) Rx(roll)``);
            zeros look horizontally along world +x, upright.
    """

    position: tuple[float, float, float] = (0.347, 0.0, 0.53)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _float_tuple(self.position, 3, "sim.start.position"))
        object.__setattr__(self, "rpy", _float_tuple(self.rpy, 3, "sim.start.rpy"))
        for axis, value in zip("xyz", self.position, strict=True):
            require_range(f"sim.start.position ({axis})", value, -1.5, 1.5)
        require_range("sim.start.rpy (pitch)", self.rpy[1], -np.pi / 2, np.pi / 2, low_open=True, high_open=True)


@dataclass(frozen=True)
class SimConfig:
    """Everything the simulated Panda needs (conf/sim/default.yaml).

    Attributes:
        seed: seed of the simulator's numpy Generator (IK restarts).
        start: the camera's start pose; None starts at the ``home`` keyframe (Franka's ready posture).
    """

    seed: int = 0
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    board: BoardConfig = field(default_factory=BoardConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    ik: IKConfig = field(default_factory=IKConfig)
    start: StartPose | None = None

    def __post_init__(self) -> None:
        require(isinstance(self.seed, int) and self.seed >= 0, "sim.seed", "a non-negative integer", self.seed)

    @classmethod
    def from_mapping(cls, cfg: Mapping[str, Any] | None) -> SimConfig:
        """Build from the ``sim`` config node (a dict or an OmegaConf ``DictConfig``)."""
        if cfg is None:
            return cls()
        if hasattr(cfg, "_get_node"):  # OmegaConf node: resolve interpolations into plain containers
            from omegaconf import OmegaConf

            cfg = OmegaConf.to_container(cfg, resolve=True)
        return from_mapping(cls, cfg, "sim")

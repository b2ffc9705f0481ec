"""The simulated Panda and its camera + IMU behind ``vical.robot``'s interfaces: the test path of ``vical-collect``.

``SimRig`` holds one simulator and one sensor drawn from the sensor distribution; ``SimArm`` and
``SimViSensor`` are the only ways in. What crosses them is what a real rig delivers: the tool pose
the arm reports, rendered grey images and IMU samples. The sensor's truth stays in the rig, for the
tests that compare a calibration with it.

Time in the simulator advances while the arm moves, waits out its command latency, or rests while
the sensor is read with nothing new to deliver (one camera period per such read), so the runner
sees the streams a real sensor delivers. Faults a real rig has are configurable: command latency (the arm rests, the
sensor streams), pose-tracking error (the arm ends a random offset away from the goal and reports
where it is), a gap in the IMU stream, and a protective stop (every goal refused).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Protocol

import numpy as np

from vical.data import NS_PER_S, ImuSamples, SensorTruth
from vical.geometry import make_transform, so3_exp
from vical.robot.interfaces import (
    Arm,
    ArmLimits,
    CameraDetections,
    CameraImage,
    MotionRefused,
    SensorData,
    StampedPose,
    ViSensor,
    check_pose,
)
from vical.sim.panda import PandaSim
from vical.sim.products import replace_board
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import SensorSampling, draw_product, sample_sensor
from vical.sim.settings import SimConfig

# The Panda's documented Cartesian limits (translation [m/s], rotation [rad/s], acceleration [m/s^2]);
# the simulator plans in joint space within sim.motion's fractions of the joint limits.
PANDA_CARTESIAN = (1.7, 2.5, 13.0)
# A goal the IK reaches this closely is executed (as a real controller's success threshold accepts it);
# beyond, the arm refuses it.
REACH_TOLERANCE_M = 0.005
REACH_TOLERANCE_RAD = np.radians(0.5)


@dataclass(frozen=True)
class RigFaults:
    """What makes the simulated rig behave like a real one.

    Attributes:
        latency: [s] between a motion command and the arm starting to move (the arm rests, the sensor streams).
        tracking_noise_m: [m] standard deviation per axis of where the arm ends relative to its goal.
        tracking_noise_rad: [rad] standard deviation per axis of the orientation it ends with.
        imu_gap: ``(start, duration)`` [s] after ``start()`` during which the IMU delivers nothing, or None.
        camera_gap: the same for the camera's frames.
        lens_covered: ``(start, duration)`` [s] after ``start()`` during which the frames come dark, without the
            board (a finger on the lens), or None.
        refuse_after: motions after which the arm refuses every goal (a protective stop), or None.
    """

    latency: float = 0.0
    tracking_noise_m: float = 0.0
    tracking_noise_rad: float = 0.0
    imu_gap: tuple[float, float] | None = None
    camera_gap: tuple[float, float] | None = None
    lens_covered: tuple[float, float] | None = None
    refuse_after: int | None = None

    def __post_init__(self) -> None:
        for name in ("latency", "tracking_noise_m", "tracking_noise_rad"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"RigFaults.{name} must be a number >= 0, got {value}")
        if self.refuse_after is not None and int(self.refuse_after) < 0:
            raise ValueError(f"RigFaults.refuse_after must be a number of motions >= 0, got {self.refuse_after}")
        for name in ("imu_gap", "camera_gap", "lens_covered"):
            gap = getattr(self, name)
            if gap is not None and (len(gap) != 2 or min(gap) < 0):
                raise ValueError(f"RigFaults.{name} must be (start, duration) in seconds >= 0, got {gap}")
            if gap is not None:
                object.__setattr__(self, name, (float(gap[0]), float(gap[1])))


class SimRig:
    """One simulated Panda holding one simulated sensor.

    Args:
        sim: the simulator's config (its board, start pose, physics).
        sampling: the sensor distribution; the rig renders images whatever its ``backend``.
        seed: draws the simulator, the sensor and its noise as ``CalibrationEnv.reset(seed=seed)`` does, so
            a rig and an env episode with the same seed hold the same sensor.
        asymmetric_distortion: draw the distortion-centre offset and tangential terms (the joint task's sensor).
        faults: latency, tracking error, IMU gap.
    """

    def __init__(
        self,
        sim: SimConfig,
        sampling: SensorSampling,
        seed: int,
        asymmetric_distortion: bool = False,
        faults: RigFaults | None = None,
    ) -> None:
        self.faults = faults or RigFaults()
        sim_seed, sensor_seed, noise_seed = np.random.default_rng(seed).integers(2**63 - 1, size=3)
        product = draw_product(sampling, int(sensor_seed))
        self.sim = PandaSim(replace(sim, board=replace_board(sim.board, product.board)))
        self.target = self.sim.cfg.board.target  # the board this rig stands before (its product's print)
        # Analytic corners are never used: the runner detects corners in the rendered images.
        self.recorder = SensorRecorder(self.sim, self.target, replace(sampling, backend="project"), keep_images=True)
        self.sim.reset(seed=int(sim_seed))
        self.truth: SensorTruth = sample_sensor(
            product.sampling, np.random.default_rng(sensor_seed), asymmetric_distortion
        )
        # What a datasheet says of the sensor (the runner's nominal values): its product's.
        self.datasheet: SensorTruth = product.datasheet
        self.recorder.start(self.truth, np.random.default_rng([int(noise_seed), 0]))
        self._tracking_rng = np.random.default_rng([int(noise_seed), 1])
        self.arm = SimArm(self)
        self.sensor = SimViSensor(self)

    def rest(self, seconds: float) -> None:
        """The arm rests ``seconds`` [s], the sensor recording."""
        self.recorder.add_motion(self.sim.hold(seconds, observer=self.recorder))

    def close(self) -> None:
        """Free the renderer."""
        self.recorder.close()


def sim_rig(
    sim: Mapping[str, Any],
    sensor: Mapping[str, Any],
    seed: int,
    asymmetric_distortion: bool = False,
    faults: Mapping[str, Any] | None = None,
) -> SimRig:
    """The ``robot=sim`` factory of ``vical-collect`` (``conf/robot/sim.yaml``): a ``SimRig`` from config mappings."""
    return SimRig(SimConfig.from_mapping(sim), SensorSampling.from_config(sensor), int(seed),
                  bool(asymmetric_distortion), RigFaults(**dict(faults or {})))  # fmt: skip


class SimArm(Arm):
    """The simulated Panda as an ``Arm``: the tool frame is the sensor body (the ``ee`` site)."""

    def __init__(self, rig: SimRig) -> None:
        self._rig = rig
        motion = rig.sim.cfg.motion
        speed, angular, acceleration = PANDA_CARTESIAN
        self.limits = ArmLimits(speed * motion.velocity_scale, angular * motion.velocity_scale,
                                acceleration * motion.acceleration_scale)  # fmt: skip
        self.stops = 0
        self.motions = 0

    def pose(self) -> StampedPose:
        sim = self._rig.sim
        return StampedPose(sim.time_ns, sim.ee_pose())

    def move_to(self, T_base_tool: np.ndarray) -> StampedPose:
        rig = self._rig
        sim, recorder, faults = rig.sim, rig.recorder, rig.faults
        if faults.refuse_after is not None and self.motions >= faults.refuse_after:
            raise MotionRefused("the arm is in a protective stop (robot.faults.refuse_after)")
        goal = self._tracked(check_pose(T_base_tool))
        ik = sim.solve_ik(goal)
        close_enough = ik.position_error <= REACH_TOLERANCE_M and ik.rotation_error <= REACH_TOLERANCE_RAD
        if not (ik.success or close_enough):
            raise MotionRefused(
                f"the goal is out of reach: the closest pose is {1e3 * ik.position_error:.1f} mm and "
                f"{np.degrees(ik.rotation_error):.1f} deg away"
            )
        fraction, touching = sim.first_collision(sim.q, ik.q)
        if touching:
            raise MotionRefused(f"the path collides ({touching}) at {100 * fraction:.0f}% of the motion")
        if faults.latency > 0:
            recorder.add_motion(sim.hold(faults.latency, observer=recorder))
        recorder.add_motion(sim.move_joints(ik.q, observer=recorder))
        self.motions += 1
        return self.pose()

    def _tracked(self, T: np.ndarray) -> np.ndarray:
        """The goal the arm actually ends at: ``T`` off by the tracking error."""
        f, rng = self._rig.faults, self._rig._tracking_rng
        if f.tracking_noise_m == 0 and f.tracking_noise_rad == 0:
            return T
        dR = so3_exp(rng.normal(0.0, f.tracking_noise_rad, 3))
        return make_transform(dR @ T[:3, :3], T[:3, 3] + rng.normal(0.0, f.tracking_noise_m, 3))

    def stop(self) -> None:
        self._rig.sim.halt()
        self.stops += 1

    def close(self) -> None:
        """Nothing to release: the rig owns the simulator (``SimRig.close``)."""


class SimClock(Protocol):
    @property
    def time_ns(self) -> int:
        """Simulated time [ns] of the current state."""


class SensorRig(Protocol):
    """What ``SimViSensor`` reads of a simulated rig (``SimRig``, ``vical.sim.hand_held.HandHeldRig``)."""

    sim: SimClock
    truth: SensorTruth
    recorder: SensorRecorder
    faults: RigFaults

    def rest(self, seconds: float) -> None:
        """Let ``seconds`` [s] pass, the sensor recording."""


def _dark(frame: CameraImage | CameraDetections) -> CameraImage | CameraDetections:
    """``frame`` as it comes with a finger on the lens: black, without the board."""
    if isinstance(frame, CameraImage):
        return CameraImage(frame.t_ns, np.zeros_like(frame.image))
    return CameraDetections(frame.t_ns, np.zeros((0, 2)), np.zeros(0, dtype=np.int64))


class SimViSensor(ViSensor):
    """The simulated camera + IMU as a ``ViSensor``: rendered grey images (the board's analytic corners where the
    rig's recorder keeps no images: a comparison at corner level), the IMU model's samples; on the arm of a
    ``SimRig`` or in the hand of a ``vical.sim.hand_held.HandHeldRig`` (their ``rest`` lets time pass, their
    ``recorder`` records, their ``faults`` apply).

    Clocks: the IMU clock is the simulation clock; camera stamps are in the camera clock, exposed at
    ``t_cam + time_offset`` (the sensor's truth). The simulation moves only as the sensor is read (``read``).
    """

    paced_by_reads = True

    def __init__(self, rig: SensorRig) -> None:
        self._rig = rig
        camera = rig.truth.camera
        self.image_size = (camera.width, camera.height)
        sampling = rig.recorder.sampling
        self.camera_rate_hz = float(sampling.camera.rate_hz)
        self.imu_rate_hz = float(sampling.imu.rate_hz)
        self._streaming = False
        self._frames_read = 0
        self._imu_read = 0
        self._t_start: int | None = None

    def start(self) -> None:
        self._streaming = True
        self._t_start = self._rig.sim.time_ns
        self._frames_read = len(self._rig.recorder.stamps_since(0))
        self._imu_read = len(self._rig.recorder.imu_samples())

    def read(self) -> SensorData:
        """The data of the last motion; when there is none, the simulation first rests one camera period
        (time passes for a sensor that is read while the arm rests)."""
        if not self._streaming:
            return SensorData.empty()
        rig = self._rig
        if len(rig.recorder.imu_samples()) == self._imu_read:
            rig.rest(1.0 / self.camera_rate_hz)
        recorder = rig.recorder
        stamps = recorder.stamps_since(self._frames_read)
        if recorder.keep_images:
            images = recorder.images_since(self._frames_read)
            frames = [CameraImage(t, image) for t, image in zip(stamps, images, strict=True)]
        else:  # corner level: the analytic detections (a comparison that needs no images)
            corners, ids = recorder.detections_since(self._frames_read)
            frames = [CameraDetections(t, uv, i) for t, uv, i in zip(stamps, corners, ids, strict=True)]
        self._frames_read += len(stamps)
        frames = [f for f, keep in zip(frames, self._outside(self._rig.faults.camera_gap, stamps), strict=True) if keep]
        frames = [f if seen else _dark(f)
                  for f, seen in zip(frames, self._outside(self._rig.faults.lens_covered, [f.t_ns for f in frames]),
                                     strict=True)]  # fmt: skip
        imu = recorder.imu_samples()
        new = np.arange(self._imu_read, len(imu))
        new = new[self._outside(self._rig.faults.imu_gap, imu.t[new])]
        self._imu_read = len(imu)
        return SensorData(frames, ImuSamples(imu.t[new], imu.gyro[new], imu.accel[new]))

    def _outside(self, gap: tuple[float, float] | None, t_ns: np.ndarray) -> np.ndarray:
        """Which of the stamps ``t_ns`` [ns] the stream delivers: those outside ``gap`` (``RigFaults``)."""
        t_ns = np.asarray(t_ns, dtype=np.int64)
        if gap is None:
            return np.ones(len(t_ns), dtype=bool)
        start = self._t_start + round(gap[0] * NS_PER_S)
        return (t_ns < start) | (t_ns >= start + round(gap[1] * NS_PER_S))

    def stop(self) -> None:
        self._streaming = False

    def close(self) -> None:
        """Nothing to release: the rig owns the renderer (``SimRig.close``)."""

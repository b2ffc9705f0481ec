"""The sensor in a simulated person's hand: the scene without the Panda, recorded as the Panda's sensor is.

``HandHeldSim`` stands where ``PandaSim`` stands for ``SensorRecorder`` (``vical.sim.recorder``): the same scene
and board (``vical.sim.scene.build_hand_held_model``: ``cam_body`` a mocap body carrying the rig the flange
carries), the same physics clock, the same observer protocol (``vical.sim.panda.StepObserver``). Its motion is
the simulated person's (``vical.sim.person.SimulatedPerson``): each physics step the rig is where the person's
hand holds it at that instant, tremor included, so the recorder makes the IMU samples (its model: averaging,
noise, bias walk, intrinsics), the camera frames (exposure instants, time offset, analytic corners or rendered
images) and the ground truth exactly as it does for the arm. Nothing collides and nothing is simulated
dynamically: a hand's motion is prescribed, not actuated. It also moves as ``PandaSim`` moves for the calibration
env (``move_to``, ``hold``, ``reset``, ``ee_pose``): each step's goal is shown to the person, who reaches it with the
hand model's error, lag and tremor (``env.hand``: a policy trained with the person's following error).

``HandHeldRig`` is one person holding one sensor drawn from the sensor distribution, as ``SimRig`` is one Panda
holding one: ``suggest`` a pose, ``advance`` the clock, read the ``recording`` (truth in it, for tests that compare
a calibration with it), or read its ``sensor`` (``vical.sim.adapters.SimViSensor``: rendered images and IMU
samples, time passing as it is read) as a live sensor is read.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from types import MappingProxyType
from typing import Any

import mujoco
import numpy as np

from vical.data import NS_PER_S, Recording, SensorTruth
from vical.geometry import invert_transform, make_transform, matrix_to_quat, quat_to_matrix
from vical.robot import Guidance, Person
from vical.sim.adapters import RigFaults, SimViSensor
from vical.sim.motion import MotionResult
from vical.sim.panda import StepObserver, StepPoses, rotation_path_length
from vical.sim.person import HandModel, Reach, SimulatedPerson
from vical.sim.products import replace_board
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import SensorSampling, draw_product, sample_sensor
from vical.sim.scene import build_hand_held_model, imu_pose_in_body, site_pose
from vical.sim.settings import SimConfig

MAX_ADVANCE_S = 60.0  # [s] the longest stretch one ``advance`` simulates (its step poses are held in memory)


class HandHeldSim:
    """The scene with ``cam_body`` in the person's hand (module doc).

    Args:
        cfg: the simulator's config (board, start pose, physics step).
        rng: draws the person (tremor now, placement errors as suggestions come).
        hand: how the person follows suggestions.

    Attributes:
        model, data: MuJoCo model and data of the scene; T_world_board: (4, 4) board pose.
        T_world_start: (4, 4) ``cam_body``'s start pose (the person's first hold); person: the simulated person.
    """

    def __init__(self, cfg: SimConfig, rng: np.random.Generator, hand: HandModel | None = None) -> None:
        self.cfg = cfg
        self.hand = hand or HandModel()
        self.model, self.T_world_board, self.T_world_start = build_hand_held_model(cfg)
        self.data = mujoco.MjData(self.model)
        self.reset(rng=rng)
        # The env moves the "ee" site (as the Panda's): the person is shown where cam_body goes for it.
        ee = self.model.site("ee")
        self._T_ee_body = invert_transform(make_transform(quat_to_matrix(ee.quat), ee.pos))

    def reset(self, seed: int | None = None, rng: np.random.Generator | None = None) -> None:
        """A new person (drawn from ``rng``, or a generator of ``seed``; neither: the next draw of the last one)
        holding the sensor at the start pose at time 0."""
        if rng is None:
            rng = self.person.rng if seed is None else np.random.default_rng(seed)
        self.person = SimulatedPerson(self.T_world_start, rng, self.hand)
        self._step = 0
        self._place(self.person.poses(np.zeros(1))[0])

    @property
    def timestep_ns(self) -> int:
        return self.cfg.physics.timestep_ns

    @property
    def time_ns(self) -> int:
        """Simulated time [ns] of the current state."""
        return self._step * self.timestep_ns

    def _place(self, T: np.ndarray) -> None:
        """Put ``cam_body`` at ``T_world_body`` ``T`` (4, 4) and update ``data``'s kinematics."""
        self.data.mocap_pos[0] = T[:3, 3]
        self.data.mocap_quat[0] = matrix_to_quat(T[:3, :3])
        mujoco.mj_forward(self.model, self.data)

    def ee_pose(self) -> np.ndarray:
        """``T_world_ee`` (4, 4) of the rig's "ee" site, where the Panda's flange would hold it."""
        return site_pose(self.model, self.data, "ee")

    def move_to(self, T_world_ee: np.ndarray, observer: StepObserver | None = None,
                settle_time: float = 0.0) -> MotionResult:  # fmt: skip
        """Show the person ``T_world_ee`` (4, 4) and simulate their reach to it (its error, lag and tremor), then
        ``settle_time`` [s] held there: ``PandaSim.move_to`` with a hand (nothing is clamped or refused)."""
        t_start_ns = self.time_ns
        reach = self.person.follow(np.asarray(T_world_ee, float) @ self._T_ee_body, t_start_ns / NS_PER_S)
        duration = min(max(0.0, reach.t_end - t_start_ns / NS_PER_S), MAX_ADVANCE_S)
        path, turn = self._advance(duration, observer)
        rest_path, rest_turn = self._advance(settle_time, observer)
        return self._motion(T_world_ee, t_start_ns, duration, settle_time, path + rest_path, turn + rest_turn)

    def hold(self, duration: float, observer: StepObserver | None = None) -> MotionResult:
        """Hold the sensor (the tremor goes on) for ``duration`` [s]."""
        t_start_ns, T_now = self.time_ns, self.ee_pose()
        path, turn = self._advance(duration, observer)
        return self._motion(T_now, t_start_ns, duration, 0.0, path, turn)

    def _motion(self, T_requested: np.ndarray, t_start_ns: int, duration: float, settle_time: float, path: float,
                turn: float) -> MotionResult:  # fmt: skip
        T_requested = np.asarray(T_requested, float)
        return MotionResult(
            reached=True, clamped=False, message="", T_requested=T_requested, T_goal=T_requested,
            T_final=self.ee_pose(), q_goal=np.zeros(0), duration=duration, settle_time=settle_time, path_length=path,
            rotation_length=turn, max_tracking_error=0.0, position_margin=np.inf, velocity_margin=np.inf,
            num_steps=(self.time_ns - t_start_ns) // self.timestep_ns, t_start_ns=t_start_ns, t_end_ns=self.time_ns,
        )  # fmt: skip

    def advance(self, seconds: float, observer: StepObserver | None = None) -> float:
        """Simulate ``seconds`` [s] of the person's motion (whole physics steps); the observer sees every step's
        poses and ``data`` at the steps it asks for, as in ``PandaSim``'s motions. Returns the path [m] of
        ``cam_body``'s origin over the steps."""
        return self._advance(seconds, observer)[0]

    def _advance(self, seconds: float, observer: StepObserver | None) -> tuple[float, float]:
        """``advance``: the path [m] and the sum of rotation angles [rad] of ``cam_body`` over the steps."""
        if not 0.0 <= seconds <= MAX_ADVANCE_S:
            raise ValueError(f"advance takes 0 to {MAX_ADVANCE_S:g} s at a time, got {seconds}")
        n, t0_ns, step_ns = round(seconds * NS_PER_S / self.timestep_ns), self.time_ns, self.timestep_ns
        if n == 0:
            return 0.0, 0.0
        T = self.person.poses((t0_ns + step_ns * np.arange(n + 1)) / NS_PER_S)  # the steps, then the end state
        live = [] if observer is None else observer.live_steps(t0_ns, n, step_ns)
        first = self._step
        for k in live:  # data describes the state at the start of step k
            self._step = first + k
            self._place(T[k])
            observer.on_live_step(self, self.time_ns)
        self._step = first + n
        self._place(T[n])
        if observer is not None:
            imu = T[:n] @ imu_pose_in_body(self.model)
            observer.on_steps(StepPoses(t0_ns, step_ns, imu[:, :3, 3].copy(), imu[:, :3, :3].reshape(n, 9).copy(),
                                        T[:n, :3, 3].copy()))  # fmt: skip
        path = float(np.sum(np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)))
        return path, rotation_path_length(T[:, :3, :3])


class HandHeldRig(Person):
    """One simulated person holding one simulated sensor before the board (module doc).

    Args:
        sim: the simulator's config (its board, start pose, physics).
        sampling: the sensor distribution (its products, where it has them, pick the board and lens).
        seed: draws the sensor, its product, its noise and the person.
        hand: how the person follows suggestions.
        keep_images: also render every frame (for a page that shows them; corners stay analytic with the
            ``project`` backend).
        asymmetric_distortion: draw the distortion-centre offset and tangential terms (the joint task's sensor).
        faults: the sensor's (no arm here: its streams' gaps), or None: none.
    """

    def __init__(
        self,
        sim: SimConfig,
        sampling: SensorSampling,
        seed: int,
        hand: HandModel | None = None,
        keep_images: bool = False,
        asymmetric_distortion: bool = False,
        faults: RigFaults | None = None,
    ) -> None:
        person_seed, sensor_seed, noise_seed = np.random.default_rng(seed).integers(2**63 - 1, size=3)
        product = draw_product(sampling, int(sensor_seed))
        self.sim = HandHeldSim(replace(sim, board=replace_board(sim.board, product.board)),
                               np.random.default_rng(person_seed), hand)  # fmt: skip
        self.target = self.sim.cfg.board.target
        self.recorder = SensorRecorder(self.sim, self.target, sampling, keep_images=keep_images)
        self.truth: SensorTruth = sample_sensor(
            product.sampling, np.random.default_rng(sensor_seed), asymmetric_distortion
        )
        self.datasheet: SensorTruth = product.datasheet  # what the person's datasheet says of the sensor
        self.recorder.start(self.truth, np.random.default_rng(noise_seed))
        self.faults = faults or RigFaults()
        self.sensor = SimViSensor(self)  # the sensor as vical-collect's runner reads one (rendered images)

    @property
    def time(self) -> float:
        """[s] since the recording started."""
        return self.sim.time_ns / NS_PER_S

    def suggest(self, T_world_body: np.ndarray) -> Reach:
        """Show the person where to hold the sensor next (``cam_body``'s pose); the reach it makes."""
        return self.sim.person.follow(T_world_body, self.time)

    def show(self, guidance: Guidance) -> None:
        """The person follows the guide (``vical.robot.Person``): to the pose it shows, in the board's frame."""
        if guidance.T_board_body is not None:
            self.suggest(self.sim.T_world_board @ guidance.T_board_body)

    def advance(self, seconds: float) -> None:
        """Let ``seconds`` [s] pass, the sensor recording as the person moves it."""
        path = self.sim.advance(seconds, self.recorder)
        self.recorder.add_time(seconds, path)

    rest = advance  # what the sensor does when it is read with nothing new: time passes (``SimViSensor``)

    def recording(self) -> Recording:
        """Everything recorded so far, with the sensor's truth."""
        return self.recorder.recording()

    def close(self) -> None:
        """Free the renderer."""
        self.recorder.close()


SENSOR_FAULTS = ("imu_gap", "camera_gap", "lens_covered")
NO_FAULTS = MappingProxyType(dict.fromkeys(SENSOR_FAULTS))  # the streams never stop


def hand_held_rig(
    sim: Mapping[str, Any],
    sensor: Mapping[str, Any],
    seed: int,
    images: bool = True,
    asymmetric_distortion: bool = False,
    faults: Mapping[str, Any] = NO_FAULTS,
    **hand: Any,
) -> HandHeldRig:
    """The ``person=sim`` factory of ``vical-guide`` (``conf/person/sim.yaml``): a simulated person (``HandModel``
    settings in ``hand``) with the simulated sensor drawn with ``seed``; ``images``: render every frame (the page's
    live image and the EuRoC recording need them; false: the board's analytic corners only); ``faults``: the
    sensor's (``RigFaults.imu_gap``, ``camera_gap``: a stream that stops, as a pulled cable's; ``lens_covered``: frames
    without the board)."""
    if "tremor_band_hz" in hand:
        hand["tremor_band_hz"] = tuple(hand["tremor_band_hz"])
    return HandHeldRig(SimConfig.from_mapping(sim), SensorSampling.from_config(sensor), int(seed), HandModel(**hand),
                       keep_images=bool(images), asymmetric_distortion=bool(asymmetric_distortion),
                       faults=sensor_faults(faults))  # fmt: skip


def sensor_faults(faults: Mapping[str, Any]) -> RigFaults:
    """The ``RigFaults`` of a held sensor's ``faults`` (its streams' gaps; an arm's faults are refused by key)."""
    unknown = sorted(set(faults) - set(SENSOR_FAULTS))
    if unknown:
        raise ValueError(f"faults: a held sensor's faults are {list(SENSOR_FAULTS)}, not {unknown}")
    return RigFaults(**faults)

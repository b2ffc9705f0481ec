"""Record a simulated sensor while the Panda moves: IMU, camera frames, ground truth -> ``Recording``.

``SensorRecorder`` is the ``PandaSim.move_to`` step observer (``vical.sim.panda.StepObserver``). It
keeps the IMU site's pose and the end effector's position of every physics step of a motion and, at
each camera exposure, observes the target from the camera pose interpolated between the two
physics steps around the exposure (the steps it asks to see live). The kept poses become the IMU
site's ideal rate and specific force (``ImuSiteReader``), the IMU model's samples
(``vical.sim.imu``), the ground-truth IMU state at the IMU sample instants and the end effector's
path in one vectorised pass whenever the IMU samples or the recording are asked for: a physics step
costs the recorder nothing, and the result does not depend on when it is asked.

Clocks. The IMU clock is the simulation clock (the steps' ``t_ns``). Camera frames are
stamped on a grid of the camera period in the camera clock; the frame stamped ``t_cam`` is
exposed at IMU time ``t_cam + time_offset`` (Kalibr's sign, ``docs/conventions.md``). A rolling
shutter (``SensorTruth.line_delay``) exposes row ``v`` ``line_delay * v`` later (row 0 at the
timestamp): the recorder keeps the camera poses of every step through the readout and sees each
corner from the pose interpolated at its row's time (``ProjectBackend.observe_rolling``), or renders
the image in bands of rows, each at its middle row's pose (``RenderBackend.rolling_image``). Only frames
whose exposure falls inside the span of the IMU samples are kept (as a hardware-synchronised
sensor would deliver them: the IMU's first sample needs its averaging window, so it starts a
few physics steps after the motion).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from vical.data import CameraFrames, ImuSamples, PathProfile, Recording, SensorTruth, Target, Trajectory
from vical.geometry import interpolate_transforms, invert_transform
from vical.sim.camera import (
    Detector,
    ProjectBackend,
    RenderBackend,
    VisibilityRules,
    interpolate_pose,
    readout_shift,
)
from vical.sim.imu import ImuSimulator, ImuSiteReader, SiteReadings, row_dot
from vical.sim.motion import MotionResult
from vical.sim.panda import PandaSim, StepPoses
from vical.sim.sampling import SensorSampling, sensor_imu_pose
from vical.sim.scene import camera_pose_cv, set_imu_pose


@dataclass
class _TruthLog:
    """Ground-truth IMU states at the IMU sample instants, in chunks of consecutive instants."""

    t: list[np.ndarray]
    T_world_imu: list[np.ndarray]
    v_world: list[np.ndarray]
    omega_imu: list[np.ndarray]


class SensorRecorder:
    """Collects one episode's sensor data from a ``PandaSim``.

    Args:
        sim: the simulator (``vical.sim.panda.PandaSim``): ``model``, ``data``, ``timestep_ns``,
            ``T_world_board``.
        target: the calibration target on the board.
        sampling: sensor settings (rates, IMU sampling mode, pixel noise, backend).
        detector: corner detector for the ``render`` backend (``detect_checkerboard``).
        keep_images: also keep the rendered grey image of every frame (renders even with the
            ``project`` backend, whose corners stay analytic).
        rules: visibility rules of the ``project`` backend.
        render_size: (W, H) [px] of the undistorted render (see ``RenderBackend``).
    """

    def __init__(
        self,
        sim: PandaSim,
        target: Target,
        sampling: SensorSampling,
        detector: Detector | None = None,
        keep_images: bool = False,
        rules: VisibilityRules | None = None,
        render_size: tuple[int, int] = (704, 528),
    ) -> None:
        if sampling.backend == "render" and detector is None:
            raise ValueError(
                "sensor.backend=render needs a corner detector (vical.calib.detection.checkerboard.detect_checkerboard)"
            )
        self.sim = sim
        self.target = target
        self.sampling = sampling
        self.keep_images = keep_images
        step_ns = int(sim.timestep_ns)
        physics = sim.cfg.physics
        self._imu_steps = physics.steps_per_period(sampling.imu.rate_hz, "sensor.imu.rate_hz")
        self._cam_period_ns = step_ns * physics.steps_per_period(sampling.camera.rate_hz, "sensor.camera.rate_hz")
        self._step_ns = step_ns
        self.project = ProjectBackend(target, sim.T_world_board, sampling.pixel_noise_px, rules)
        T_world_board = np.asarray(sim.T_world_board, dtype=float)
        self._board_points = target.points @ T_world_board[:3, :3].T + T_world_board[:3, 3]  # a readout's image shift
        needs_render = sampling.backend == "render" or keep_images
        self.render = RenderBackend(sim.model, target, detector, render_size) if needs_render else None
        model = sim.model
        self._reader = ImuSiteReader(model)
        self.truth: SensorTruth | None = None
        self.others: dict[str, SensorTruth] = {}  # a rig's other cameras (start)
        self._other_render: dict[str, RenderBackend] = {}
        self._other_frames: dict[str, dict[str, list]] = {}

    # ------------------------------------------------------------------ episode
    def start(
        self, truth: SensorTruth, rng: np.random.Generator, others: Mapping[str, SensorTruth] | None = None
    ) -> None:
        """Begin an episode with sensor ``truth``: places the IMU site, prepares the camera, clears the data.

        Call before the first motion of the episode (after ``sim.reset``); ``rng`` draws the IMU
        and pixel noise. ``others``: a rig's other cameras by name (``vical.sim.sampling.sample_rig``), exposed
        with the first one (its stamps, its time offset), each from its own pose through its own lens.
        """
        for camera in [truth.camera] + [o.camera for o in (others or {}).values()]:
            if camera.width != self.sampling.camera.width or camera.height != self.sampling.camera.height:
                raise ValueError(
                    f"sensor camera is {camera.width} x {camera.height} px but the recorder is set up for "
                    f"{self.sampling.camera.width} x {self.sampling.camera.height} (sensor.camera.width/height)"
                )
        self.truth = truth
        self._start_others(dict(others or {}))
        cameras = [truth, *self.others.values()]
        self._readout_ns = max(round(c.line_delay * c.camera.height * 1e9) for c in cameras)
        set_imu_pose(self.sim.model, sensor_imu_pose(truth))
        mujoco.mj_forward(self.sim.model, self.sim.data)
        self._reader.reset(self.sim.time_ns)
        imu_rng, self._cam_rng = rng.spawn(2)
        self._imu = ImuSimulator(
            self._step_ns,
            self._imu_steps,
            self.sampling.imu.sampling,
            truth.imu_noise,
            imu_rng,
            truth.gyro_bias,
            truth.accel_bias,
            None if truth.imu_intrinsics.is_identity() else truth.imu_intrinsics,
        )
        if self.render is not None:
            self.render.set_camera(truth.camera)
        self._offset_ns = round(truth.time_offset * 1e9)
        self._next_stamp: int | None = None
        self._window: list[tuple[int, np.ndarray]] = []  # (t_ns, T_world_cam) of the steps through an exposure
        self._frames: dict[str, list] = _no_frames()
        self._log = _TruthLog([], [], [], [])
        self._path_length = 0.0
        self._duration = 0.0
        self._ee_steps: list[np.ndarray] = []  # end-effector positions (K_i, 3) of the steps not yet on the path
        self._ee_t0_ns = self.sim.time_ns  # time of the first of them (the reader refuses a skipped step)
        self._ee_last: np.ndarray | None = None
        self._ee_path = 0.0
        self._path_log: tuple[list[np.ndarray], list[np.ndarray]] = ([], [])

    def live_steps(self, t0_ns: int, num_steps: int, step_ns: int) -> list[int]:
        """The steps of a motion through each camera exposure: from the one it starts in to the first at or after
        its readout's end (with a global shutter: the one it falls in and the first at or after it)."""
        self._require_started("a motion")
        self._reader.check_next(t0_ns)  # before the motion runs: it must follow the steps recorded so far
        if self._next_stamp is None:
            self._next_stamp = self._first_stamp(t0_ns)
        steps, stamp = set(), self._next_stamp
        while (exposure := stamp + self._offset_ns) < t0_ns + num_steps * step_ns:
            within = (exposure - t0_ns) // step_ns
            after = -((t0_ns - exposure - self._readout_ns) // step_ns)
            steps |= set(range(max(within, 0), min(after, num_steps - 1) + 1))
            stamp += self._cam_period_ns
        return sorted(steps)

    def on_live_step(self, sim: PandaSim, t_ns: int) -> None:
        """``data``'s derived quantities belong to time ``t_ns``: keep the camera pose of a step through an exposure,
        and observe once the exposure (its readout) is over."""
        exposure = self._next_stamp + self._offset_ns
        if t_ns <= exposure < t_ns + self._step_ns:
            self._window = [(t_ns, camera_pose_cv(sim.model, sim.data))]
        elif self._window:
            self._window.append((t_ns, camera_pose_cv(sim.model, sim.data)))
        if self._window and t_ns >= exposure + self._readout_ns:
            self._observe(self._next_stamp, exposure)
            self._next_stamp += self._cam_period_ns
            self._window = []

    def on_steps(self, poses: StepPoses) -> None:
        """Keep the IMU site's poses and the end effector's positions of a motion's physics steps."""
        self._reader.record_steps(poses.t0_ns, poses.step_ns, poses.imu_p, poses.imu_R)  # refuses skipped steps
        self._ee_steps.append(poses.ee_p)

    def add_motion(self, result: MotionResult) -> None:
        """Account a finished ``MotionResult`` (path length [m] and time [s]) to the recording."""
        self.add_time(result.duration + result.settle_time, result.path_length)

    def add_time(self, duration: float, path_length: float) -> None:
        """Account ``duration`` [s] of recording and ``path_length`` [m] of the sensor's path to the recording."""
        self._path_length += float(path_length)
        self._duration += float(duration)

    def detections_since(self, first: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Corners (K_i, 2) [px] and point ids (K_i,) of the frames observed from index ``first`` on.

        For consumers that follow the data while it is recorded (the calibration environment's
        coverage); frames are counted from ``start`` in observation order.
        """
        return self._frames["corners"][first:], self._frames["ids"][first:]

    def stamps_since(self, first: int) -> list[int]:
        """Camera timestamps [ns] (camera clock) of the frames observed from index ``first`` on."""
        return self._frames["t"][first:]

    def images_since(self, first: int) -> list[np.ndarray]:
        """Grey images (H, W) of the frames observed from index ``first`` on (``keep_images=True`` only)."""
        if not self.keep_images:
            raise RuntimeError("SensorRecorder.images_since needs keep_images=True")
        return self._frames["images"][first:]

    def imu_samples(self) -> ImuSamples:
        """The IMU samples recorded so far (for consumers that follow the data while it is recorded)."""
        self._require_started("imu_samples()")
        self._catch_up()
        return self._imu.samples()

    def recording(self, metadata: dict[str, Any] | None = None) -> Recording:
        """Everything recorded since ``start``; the trajectory holds the truth at the IMU sample times."""
        self._require_started("recording()")
        imu = self.imu_samples()
        return Recording(
            imu=imu,
            frames=self._camera_frames(self._frames, imu),
            other_frames={name: self._camera_frames(f, imu) for name, f in self._other_frames.items()},
            other_truths=dict(self.others),
            target=self.target,
            truth=self.truth,
            trajectory=self._trajectory(imu),
            T_world_target=np.array(self.sim.T_world_board, dtype=float),
            path_length=self._path_length,
            duration=self._duration,
            metadata=dict(metadata or {}),
            path_profile=PathProfile(_joined(self._path_log[0], np.int64), _joined(self._path_log[1], float)),
        )

    # ------------------------------------------------------------------ internals
    def _require_started(self, call: str) -> None:
        if self.truth is None:
            raise RuntimeError(f"SensorRecorder.start(truth, rng) must be called before {call}")

    def _first_stamp(self, t_ns: int) -> int:
        """First camera stamp on the camera-period grid whose exposure is at or after ``t_ns``."""
        period = self._cam_period_ns
        return -(-(t_ns - self._offset_ns) // period) * period

    def _start_others(self, others: dict[str, SensorTruth]) -> None:
        """The rig's other cameras: their truths, a renderer each where images are made, their frames cleared."""
        for render in self._other_render.values():
            render.close()
        self.others = others
        self._other_render = {}
        if self.render is not None:
            for name, other in others.items():
                self._other_render[name] = RenderBackend(self.sim.model, self.target, self.render.detector,
                                                         self.render.size)  # fmt: skip
                self._other_render[name].set_camera(other.camera)
        self._other_frames = {name: _no_frames() for name in others}

    def _observe(self, stamp: int, exposure: int) -> None:
        """Every camera's exposure of the frame ``stamp`` from the window's poses (exposure at ``exposure`` [ns])."""
        # The exposure (row 0's) falls in the window's first step: the pose there is between it and the next step
        # (the only one with a global shutter; a rolling shutter's window runs on through its readout).
        (t0, T0), (t1, T1) = self._window[0], self._window[min(1, len(self._window) - 1)]
        T_world_cam = interpolate_pose(exposure, t0, T0, t1, T1)
        times = np.array([t for t, _ in self._window], dtype=float)
        poses = np.array([T for _, T in self._window])

        def pose_at(dt: np.ndarray) -> np.ndarray:  # the cam0 poses dt [s] after the exposure (a rolling shutter's)
            return interpolate_transforms(times, poses, exposure + np.asarray(dt) * 1e9)

        self._observe_camera(self._frames, self.truth, self.render, stamp, T_world_cam, pose_at)
        for name, other in self.others.items():
            T_cam0_cam = self.truth.T_cam_imu @ invert_transform(other.T_cam_imu)
            frames, render = self._other_frames[name], self._other_render.get(name)
            self._observe_camera(
                frames, other, render, stamp, T_world_cam @ T_cam0_cam, lambda dt, c=T_cam0_cam: pose_at(dt) @ c
            )

    def _observe_camera(self, frames: dict[str, list], truth: SensorTruth, render, stamp: int, T_world_cam, pose_at):
        """One camera's exposure at pose ``T_world_cam`` (its rows' poses ``pose_at``, a rolling shutter's): its
        corners (and image) appended to ``frames``."""
        image, camera, delay = None, truth.camera, truth.line_delay
        shift = readout_shift(camera, self._board_points, pose_at, delay) if delay > 0 and render is not None else 0.0
        if self.sampling.backend == "render":
            if delay > 0:
                corners, ids, image = render.observe_rolling(self.sim.data, pose_at, delay, shift)
            else:
                corners, ids, image = render.observe(self.sim.data, T_world_cam)
        else:
            if delay > 0:
                corners, ids = self.project.observe_rolling(camera, pose_at, delay, self._cam_rng)
            else:
                corners, ids = self.project.observe(camera, T_world_cam, self._cam_rng)
            if self.keep_images:
                image = (
                    render.rolling_image(self.sim.data, pose_at, delay, shift)
                    if delay > 0
                    else render.image(self.sim.data, T_world_cam)
                )
        frames["t"].append(stamp)
        frames["corners"].append(corners)
        frames["ids"].append(ids)
        if self.keep_images:
            frames["images"].append(image)

    def _catch_up(self) -> None:
        """Turn the poses kept since the last call into IMU readings, truth and path."""
        site = self._reader.readings()
        if len(site.t_ns):
            self._imu.add_readings(int(site.t_ns[0]), site.reading)
            self._log_truth(site)
        if self._ee_steps:
            self._follow_path()

    def _at_imu_instants(self, t_ns: np.ndarray) -> np.ndarray:
        return np.flatnonzero(t_ns % (self._imu_steps * self._step_ns) == 0)

    def _follow_path(self) -> None:
        """Add the end effector's kept steps to its path; log the path at the IMU sample instants."""
        p = np.concatenate(self._ee_steps)
        before = p[:1] if self._ee_last is None else self._ee_last[None]  # the first step moves nowhere
        d = p - np.vstack([before, p[:-1]])
        # sqrt(d_i @ d_i) per row: the floats np.linalg.norm gives one step at a time.
        steps = np.sqrt(row_dot(d, d))
        path = np.cumsum(np.concatenate([[self._ee_path], steps]))[1:]  # sequential, as step-by-step sums
        t_ns = self._ee_t0_ns + self._step_ns * np.arange(len(p), dtype=np.int64)
        logged = self._at_imu_instants(t_ns)
        self._path_log[0].append(t_ns[logged])
        self._path_log[1].append(path[logged])
        self._ee_last, self._ee_path, self._ee_steps = p[-1], float(path[-1]), []
        self._ee_t0_ns = int(t_ns[-1]) + self._step_ns

    def _log_truth(self, site: SiteReadings) -> None:
        logged = self._at_imu_instants(site.t_ns)
        T = np.zeros((len(logged), 4, 4))
        T[:, :3, :3] = site.R_world_site[logged]
        T[:, :3, 3] = site.p_world[logged]
        T[:, 3, 3] = 1.0
        log = self._log
        log.t.append(site.t_ns[logged])
        log.T_world_imu.append(T)
        log.v_world.append(site.v_world[logged])
        log.omega_imu.append(site.omega_site[logged])

    def _trajectory(self, imu: ImuSamples) -> Trajectory:
        log = self._log
        t = _joined(log.t, np.int64)
        take = np.flatnonzero(np.isin(t, imu.t))
        return Trajectory(
            t=t[take],
            T_world_imu=_joined(log.T_world_imu, float, (4, 4))[take],
            v_world=_joined(log.v_world, float, (3,))[take],
            omega_imu=_joined(log.omega_imu, float, (3,))[take],
        )

    def _camera_frames(self, f: dict[str, list], imu: ImuSamples) -> CameraFrames:
        images = np.asarray(f["images"], dtype=np.uint8) if self.keep_images and f["images"] else None
        frames = CameraFrames(np.asarray(f["t"], dtype=np.int64), f["corners"], f["ids"], images)
        if not len(imu):
            return frames
        exposure = frames.t + self._offset_ns
        return frames.select((exposure >= imu.t[0]) & (exposure <= imu.t[-1]))

    def close(self) -> None:
        """Free the renderers' GL contexts."""
        for render in [self.render, *self._other_render.values()]:
            if render is not None:
                render.close()


def _no_frames() -> dict[str, list]:
    return {"t": [], "corners": [], "ids": [], "images": []}


def _joined(chunks: list[np.ndarray], dtype: type, row: tuple[int, ...] = ()) -> np.ndarray:
    """The chunks (K_i, *row) stacked into one (sum K_i, *row) array of ``dtype`` (empty when none)."""
    return np.concatenate(chunks).astype(dtype, copy=False) if chunks else np.zeros((0, *row), dtype=dtype)

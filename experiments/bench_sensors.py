"""Sensor simulation speed and the IMU sampling choice, on one ~1 s motion of the Panda.

Prints three tables:

1. Wall time per physics step of bare physics, of physics + the full recorder (IMU and ``project``
   camera), and what the ``project`` backend costs per frame and amortised per step (target:
   < 10 % of the physics time of a step).
2. Wall time per frame of the ``render`` backend (render + warp + detection) next to a bare
   ``mujoco.Renderer.render`` of the same scene at 640 x 480 in the same run (target: <= 25 ms),
   for two render sizes, with the render-vs-project corner agreement.
3. IMU sampling: how much of the physics-rate readings lies above the IMU's Nyquist frequency
   (what ``instant`` sampling folds into the 200 Hz stream) and how far ``instant`` samples lie
   from ``average`` samples, next to the white-noise sigma per sample.
4. A static IMU recording (``vical-record mode=static_imu``): 2 h at 200 Hz generated in closed form and
   written as an EuRoC folder (target: <= 1 min), next to the simulated arm holding still with its IMU
   recording (physics + recorder) for 10 s in the same run, scaled to 2 h.

Usage: ``python experiments/bench_sensors.py [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np

from vical.calib.detection.checkerboard import detect_checkerboard
from vical.data import ImuNoise
from vical.geometry import euler_to_matrix, make_transform
from vical.io.euroc import write_euroc_imu
from vical.sim import PandaSim, camera_pose_cv
from vical.sim.camera import ProjectBackend, RenderBackend
from vical.sim.imu import ImuSiteReader, discrete_sigmas, static_imu
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import SensorSampling, sample_sensor

# About 1 s of motion at the default joint-limit scaling.
GOAL = make_transform(euler_to_matrix([0.3, -0.25, 0.35]), [0.1, -0.12, 0.08])


def _move(sim: PandaSim, observer=None) -> tuple[float, int]:
    """Wall time [s] and physics steps of the benchmark motion from home."""
    sim.reset()
    T = sim.ee_pose() @ GOAL
    start = time.perf_counter()
    result = sim.move_to(T, observer=observer)
    return time.perf_counter() - start, result.num_steps


def physics_table(sim: PandaSim, sampling: SensorSampling, repeats: int) -> list[tuple[str, float]]:
    truth = sample_sensor(sampling, np.random.default_rng(0))
    bare = min(_move(sim)[0] for _ in range(repeats))
    _, steps = _move(sim)
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling)

    def recorded() -> float:
        sim.reset()
        recorder.start(truth, np.random.default_rng(1))
        return _move(sim, recorder)[0]

    full = min(recorded() for _ in range(repeats))
    frames = len(recorder.recording().frames)
    # The project backend alone, on the camera poses of the motion.
    poses = []
    sim.reset()
    sim.move_to(sim.ee_pose() @ GOAL, on_step=lambda s, t: poses.append(camera_pose_cv(s.model, s.data)))
    project = ProjectBackend(sim.cfg.board.target, sim.T_world_board, sampling.pixel_noise_px)
    rng = np.random.default_rng(2)
    start = time.perf_counter()
    for T in poses[::100]:
        project.observe(truth.camera, T, rng)
    per_frame = (time.perf_counter() - start) / len(poses[::100])
    per_step = bare / steps
    return [
        ("motion", f"{steps} physics steps, {frames} camera frames"),
        ("move_to physics + control, no sensors [us/step]", f"{1e6 * per_step:.1f}"),
        ("move_to + recorder (IMU + project) [us/step]", f"{1e6 * full / steps:.1f}"),
        ("recorder overhead [% of move_to]", f"{100 * (full - bare) / bare:.1f}"),
        ("project backend [us/frame]", f"{1e6 * per_frame:.1f}"),
        ("project backend amortised [% of a move_to step]", f"{100 * per_frame * frames / steps / per_step:.2f}"),
    ]


def render_table(sim: PandaSim, sampling: SensorSampling, repeats: int) -> list[tuple[str, str]]:
    sim.reset()
    target = sim.cfg.board.target
    bare = mujoco.Renderer(sim.model, height=480, width=640)
    rows = []
    try:
        bare.update_scene(sim.data, camera="cam")
        bare.render()
        start = time.perf_counter()
        for _ in range(10 * repeats):
            bare.update_scene(sim.data, camera="cam")
            bare.render()
        rows.append(
            (
                "bare mujoco.Renderer.render 640x480 [ms/frame]",
                f"{1e3 * (time.perf_counter() - start) / (10 * repeats):.1f}",
            )
        )
    finally:
        bare.close()
    camera = sample_sensor(sampling, np.random.default_rng(3)).camera
    T_home = camera_pose_cv(sim.model, sim.data)
    views = [T_home @ make_transform(euler_to_matrix(rpy), xyz) for rpy, xyz in _views()]
    project = ProjectBackend(target, sim.T_world_board, 0.0)
    for size in ((704, 528), (800, 600)):
        backend = RenderBackend(sim.model, target, detect_checkerboard, render_size=size)
        try:
            rows.extend(_render_rows(sim, backend, camera, views, project, size, repeats))
        finally:
            backend.close()
    return rows


def _views() -> list[tuple[list[float], list[float]]]:
    rng = np.random.default_rng(4)
    return [(rng.uniform(-0.15, 0.15, 3).tolist(), rng.uniform(-0.15, 0.15, 3).tolist()) for _ in range(10)]


def _render_rows(sim, backend, camera, views, project, size, repeats) -> list[tuple[str, str]]:
    start = time.perf_counter()
    backend.set_camera(camera)
    maps_s = time.perf_counter() - start
    times = {"render": 0.0, "warp": 0.0, "detect": 0.0}
    errors = []
    for _ in range(repeats):
        for T in views:
            t0 = time.perf_counter()
            image = backend.image(sim.data, T)
            t1 = time.perf_counter()
            corners, ids = detect_checkerboard(image, backend.target)
            t2 = time.perf_counter()
            times["render"] += t1 - t0
            times["detect"] += t2 - t1
            ideal = project.ideal_corners(camera, T)
            if ideal is not None and len(ids):
                errors.append(corners - ideal[ids])
    n = repeats * len(views)
    rms = float(np.sqrt(np.mean(np.sum(np.vstack(errors) ** 2, axis=1)))) if errors else float("nan")
    label = f"render backend {size[0]}x{size[1]}"
    return [
        (f"{label}: render + warp [ms/frame]", f"{1e3 * times['render'] / n:.1f}"),
        (f"{label}: detection [ms/frame]", f"{1e3 * times['detect'] / n:.1f}"),
        (f"{label}: total [ms/frame]", f"{1e3 * (times['render'] + times['detect']) / n:.1f}"),
        (f"{label}: vs project [px RMS, {len(errors)} views]", f"{rms:.3f}"),
        (f"{label}: warp maps per sensor [s]", f"{maps_s:.2f}"),
    ]


def imu_sampling_table(sim: PandaSim) -> list[tuple[str, str]]:
    """Physics-rate readings of the motion, split at the IMU Nyquist frequency; instant vs average."""
    sim.reset()
    reader = ImuSiteReader(sim.model)
    reader.reset(sim.time_ns)
    sim.move_to(sim.ee_pose() @ GOAL, on_step=lambda s, t: reader.record(s.data, t, s.timestep_ns))
    x = reader.readings().reading  # (K, 6) gyro, accel at 1 kHz
    rate = 1e9 / sim.timestep_ns
    high = _above(x, rate, 100.0)
    n = round(rate / 200.0)
    centres = np.arange(n, len(x) - n, n)
    instant = x[centres]
    average = np.mean([x[centres + k] for k in range(-(n // 2), n // 2 + 1)], axis=0)
    sig = discrete_sigmas(ImuNoise())
    rms = lambda a: np.sqrt(np.mean(a**2, axis=0))  # noqa: E731
    return [
        ("gyro content above 100 Hz [rad/s RMS]", f"{rms(high[:, :3]).max():.2e}"),
        ("accel content above 100 Hz [m/s^2 RMS]", f"{rms(high[:, 3:]).max():.2e}"),
        ("gyro instant - average [rad/s RMS]", f"{rms(instant[:, :3] - average[:, :3]).max():.2e}"),
        ("accel instant - average [m/s^2 RMS]", f"{rms(instant[:, 3:] - average[:, 3:]).max():.2e}"),
        ("gyro white noise per sample [rad/s]", f"{sig['gyro_white']:.2e}"),
        ("accel white noise per sample [m/s^2]", f"{sig['accel_white']:.2e}"),
    ]


def _above(x: np.ndarray, rate: float, cutoff: float) -> np.ndarray:
    """Content of ``x`` (K, C) above ``cutoff`` [Hz]; the line through the end points is removed first so
    that the periodic extension the FFT assumes has no jump (which would leak into every frequency)."""
    ramp = np.linspace(0.0, 1.0, len(x))[:, None]
    detrended = x - (x[0] + ramp * (x[-1] - x[0]))
    spectrum = np.fft.rfft(detrended, axis=0)
    spectrum[np.fft.rfftfreq(len(x), 1.0 / rate) <= cutoff] = 0.0
    return np.fft.irfft(spectrum, n=len(x), axis=0)


def static_table(sim: PandaSim, sampling: SensorSampling) -> list[tuple[str, str]]:
    truth = sample_sensor(sampling, np.random.default_rng(0))
    hours = 2.0
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        chunks = static_imu(truth, np.random.default_rng(1), hours * 3600)
        write_euroc_imu(Path(tmp) / "static", chunks, truth.imu_noise, truth.imu_noise.rate_hz, "bench")
        closed = time.perf_counter() - start
        size = (Path(tmp) / "static" / "mav0" / "imu0" / "data.csv").stat().st_size
    sim.reset()
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling)
    recorder.start(truth, np.random.default_rng(1))
    held = 10.0
    start = time.perf_counter()
    sim.hold(held, observer=recorder)
    physics = (time.perf_counter() - start) * hours * 3600 / held
    recorder.close()
    rate = truth.imu_noise.rate_hz
    return [
        (f"closed form + EuRoC CSV, {hours:g} h at {rate:g} Hz [s]", f"{closed:.1f} ({size / 1e6:.0f} MB)"),
        (f"the arm at rest in physics + recorder, scaled to {hours:g} h [s]", f"{physics:.0f}"),
        ("ratio", f"{physics / closed:.0f}x"),
    ]


def _print(title: str, rows: list[tuple[str, str]]) -> None:
    width = max(len(k) for k, _ in rows)
    print(f"\n{title}\n" + "-" * (width + 20))
    for key, value in rows:
        print(f"{key:<{width}}  {value}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="repetitions (the minimum time is reported)")
    args = parser.parse_args()
    sim = PandaSim()
    sampling = SensorSampling()
    _print("Physics + IMU + project backend", physics_table(sim, sampling, args.repeats))
    _print("Render backend vs bare mujoco.Renderer (same scene, same run)", render_table(sim, sampling, args.repeats))
    _print("IMU sampling: instant vs interval average (noise-free readings)", imu_sampling_table(sim))
    _print("A static IMU recording: closed form vs the simulated arm at rest (same run)", static_table(sim, sampling))


if __name__ == "__main__":
    main()

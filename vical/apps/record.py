"""``vical-record``: move the simulated Panda through pose steps and write a recording (``conf/record.yaml``).

The sensor is drawn from the ``sensor`` group with the run's seed (the distortion centre only
where ``task.asymmetric_distortion`` says so); the arm executes ``steps`` in MuJoCo physics while
the IMU and camera record; the result is written atomically as a ``vical.io.save_recording``
directory, with ``images=true`` also the rendered frames as ``<out>/images/<t_ns>.png`` (the same
directory, so a killed run leaves no recording without its images). A step the arm cannot execute
as requested (unreachable, or stopped short of a contact) is executed as far as it goes, with a
warning that compares it with the request.

User errors (a bad value, an existing ``out``, Hydra's own override errors) print one line
``vical-record: error: ...`` and exit with status 2, checked before the simulator starts.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from vical.apps.cli import (
    OutputError,
    check_creatable,
    check_then_run,
    fail,
    plain,
    task_begins,
    write_faults_in_one_line,
)
from vical.apps.entry import run as run_command
from vical.calib.detection.aprilgrid import detect_aprilgrid
from vical.calib.detection.checkerboard import detect_checkerboard
from vical.calib.solve.intrinsics import MIN_VIEWS
from vical.config_checks import ConfigError, require, require_range
from vical.data import CameraFrames, Recording
from vical.geometry import CameraModel, matrix_to_euler, step_pose
from vical.io.atomic import atomic_directory
from vical.io.euroc import write_euroc_imu
from vical.io.images import write_png
from vical.io.recording import write_recording_files
from vical.sim import MotionResult, PandaSim, SimConfig
from vical.sim.camera import VisibilityRules
from vical.sim.imu import STATIC_CHUNK_S, static_imu
from vical.sim.products import replace_board
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import SensorSampling, draw_product, sample_rig, sample_sensor
from vical.sim.settings import BoardConfig

APP = "vical-record"
USER_ERRORS = (ConfigError, FileExistsError, OutputError)


class ClampedStepWarning(UserWarning):
    """A pose step the arm could not execute as requested; the message compares the two."""


class FewViewsWarning(UserWarning):
    """Fewer frames with board corners than a calibration needs; the message says what to change."""


def parse_steps(steps) -> np.ndarray:
    """``steps`` as an (S, 6) float array; ``ConfigError`` naming the bad entry otherwise."""
    ok = isinstance(steps, list | tuple) and len(steps) > 0
    require(ok, "steps", "a non-empty list of [dx, dy, dz, droll, dpitch, dyaw]", steps)
    parsed = []
    for i, step in enumerate(steps):
        try:
            row = np.asarray(list(step), dtype=float)
        except (TypeError, ValueError):
            raise ConfigError(f"steps[{i}] must be 6 numbers [dx, dy, dz, droll, dpitch, dyaw], got {step!r}") from None
        require(row.shape == (6,) and bool(np.all(np.isfinite(row))), f"steps[{i}]", "6 finite numbers", list(step))
        parsed.append(row)
    return np.array(parsed)


def check_out(out, overwrite: bool) -> Path:
    """``out`` as a Path; refused when it is a file, lies below one, or exists and ``overwrite`` is false."""
    require(isinstance(out, str) and bool(out), "out", "a directory path", out)
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise FileExistsError(f"out={out} is a file; choose a directory path")
    if path.exists() and not overwrite:
        raise FileExistsError(f"out={out} already exists; choose another directory or pass overwrite=true")
    return check_creatable("out=", path)


def _require_bool(cfg: DictConfig, key: str) -> bool:
    value = cfg.get(key)
    require(isinstance(value, bool), key, "true or false", value)
    return value


def _render_size(value) -> tuple[int, int]:
    ok = isinstance(value, list | tuple) and len(value) == 2
    ok = ok and all(isinstance(v, int) and not isinstance(v, bool) and v >= 16 for v in value)
    require(ok, "render_size", "[width, height], two integers >= 16 [px]", value)
    return int(value[0]), int(value[1])


def _seed(value) -> int:
    require(isinstance(value, int) and not isinstance(value, bool) and value >= 0, "seed", "an integer >= 0", value)
    return value


def clamp_warning(i: int, T_start: np.ndarray, result: MotionResult) -> str:
    """What step ``i`` asked for and what the arm executed instead, from the pose ``T_start`` (4, 4)."""

    def motion(T: np.ndarray) -> str:
        translation = np.linalg.norm(T[:3, 3] - T_start[:3, 3])
        turn = np.degrees(matrix_to_euler(T[:3, :3]) - matrix_to_euler(T_start[:3, :3]))
        rotation = np.round((turn + 180.0) % 360.0 - 180.0, 1) + 0.0  # + 0.0: no -0.0
        return f"{translation:.3f} m, Euler increments [{rotation[0]:+.1f} {rotation[1]:+.1f} {rotation[2]:+.1f}] deg"

    return (
        f"steps[{i}] was not executed as requested ({result.message}): it asked for {motion(result.T_requested)}, "
        f"the arm moved {motion(result.T_goal)}; the recording holds the executed motion"
    )


def few_views_warning(frames: CameraFrames, camera: CameraModel, board: BoardConfig) -> str | None:
    """What to change when fewer than ``MIN_VIEWS`` frames hold board corners (None otherwise).

    The recording is written all the same (its motion and IMU data are sound). Squares below what the
    detector resolves (``VisibilityRules``, which the ``project`` backend applies too) point at the
    board's distance and size; larger ones at the board out of view.
    """
    seen = int(np.count_nonzero(frames.num_detections))
    if seen >= MIN_VIEWS:
        return None
    few = f"{seen} of {len(frames)} frames hold board corners, fewer than the {MIN_VIEWS} views a calibration needs"
    rules = VisibilityRules()
    smallest = rules.min_tag_px if board.kind == "aprilgrid" else rules.min_corner_spacing_px
    size = square_px(camera, board)
    if size < smallest:
        return (
            f"{few}: the board's squares are about {size:.1f} px wide at the start pose, below the {smallest:g} px "
            f"the detector resolves; bring the board closer (sim.board.distance, now {board.distance:g} m) or "
            f"enlarge it (sim.board.square, now {board.square:g} m)"
        )
    return f"{few}: keep the board in view (steps, sim.board.offset; its squares are about {size:.0f} px wide)"


def square_px(camera: CameraModel, board: BoardConfig) -> float:
    """[px] the width of one board square (aprilgrid: tag) in the image centre at the board's start distance."""
    ends = np.array([[0.0, 0.0, board.distance], [board.square, 0.0, board.distance]])
    uv, _ = camera.project(ends)
    return float(np.linalg.norm(uv[1] - uv[0]))


def write_images(recording: Recording, out: Path) -> None:
    """Write every frame's image as ``<out>/images/<t_ns>.png`` (a rig's other cameras: ``images_camN/``)."""
    for name in recording.camera_names:
        folder = out / ("images" if name == "cam0" else f"images_{name}")
        folder.mkdir()
        frames = recording.frames_of(name)
        for t, image in zip(frames.t, frames.images, strict=True):
            write_png(folder / f"{int(t)}.png", image)


MODES = ("steps", "static_imu")
MAX_STATIC_DURATION = 48 * 3600.0  # [s] two days: longer than any Allan deviation needs


@dataclass(frozen=True)
class RecordSettings:
    """The checked settings of one recording (``conf/record.yaml``)."""

    mode: str
    static_duration: float  # [s]
    steps: np.ndarray  # (S, 6) pose steps
    seed: int
    out: Path
    overwrite: bool
    images: bool
    progress: bool
    render_size: tuple[int, int]
    settle_time: float
    sampling: SensorSampling
    sim: SimConfig
    asymmetric_distortion: bool


def check_settings(cfg: DictConfig) -> RecordSettings:
    """Every setting of ``cfg`` checked, so that a bad one stops the run before the simulator starts."""
    overwrite, images, progress = (_require_bool(cfg, key) for key in ("overwrite", "images", "progress"))
    settle_time = cfg.get("settle_time")
    require_range("settle_time", settle_time, 0.0, 60.0)
    mode, static_duration = cfg.get("mode"), cfg.get("static_duration")
    require(mode in MODES, "mode", f"one of {list(MODES)}", mode)
    require_range("static_duration", static_duration, 0.0, MAX_STATIC_DURATION, low_open=True)
    return RecordSettings(
        mode=mode,
        static_duration=float(static_duration),
        steps=parse_steps(plain(cfg.get("steps"))),
        seed=_seed(cfg.get("seed")),
        out=check_out(cfg.get("out"), overwrite),
        overwrite=overwrite,
        images=images,
        progress=progress,
        render_size=_render_size(plain(cfg.get("render_size"))),
        settle_time=float(settle_time),
        sampling=SensorSampling.from_config(OmegaConf.to_container(cfg.sensor, resolve=True)),
        sim=SimConfig.from_mapping(cfg.sim),
        asymmetric_distortion=bool(cfg.task.asymmetric_distortion),
    )


def record(cfg: DictConfig) -> Path:
    """Run the motion of ``cfg`` with a sampled sensor and write the recording (``mode=static_imu``: the IMU at
    rest, ``record_static_imu``); return its directory."""
    s = check_settings(cfg)
    if s.mode == "static_imu":
        return record_static_imu(s)
    product = draw_product(s.sampling, s.seed)
    sim = PandaSim(replace(s.sim, board=replace_board(s.sim.board, product.board)))
    rng = np.random.default_rng(s.seed)
    truth = sample_sensor(product.sampling, rng, asymmetric=s.asymmetric_distortion)
    others = sample_rig(product.sampling, rng, truth)  # sensor.rig's cameras (none: nothing drawn)
    detector = detect_aprilgrid if sim.cfg.board.kind == "aprilgrid" else detect_checkerboard
    detector = detector if s.sampling.backend == "render" else None
    recorder = SensorRecorder(sim, sim.cfg.board.target, s.sampling, detector, s.images, render_size=s.render_size)
    try:
        recorder.start(truth, rng, others)
        for i, step in enumerate(tqdm(s.steps, desc=APP, unit="step", disable=not s.progress)):
            T_start = sim.ee_pose()
            T_goal = step_pose(T_start, step[:3], step[3:])
            result = sim.move_to(T_goal, observer=recorder, settle_time=s.settle_time)
            recorder.add_motion(result)
            if result.clamped:
                warnings.warn(clamp_warning(i, T_start, result), ClampedStepWarning, stacklevel=2)
        metadata = {"seed": s.seed, "config": OmegaConf.to_container(cfg, resolve=True)}
        recording = recorder.recording(metadata)
    finally:
        recorder.close()
    problem = few_views_warning(recording.frames, truth.camera, sim.cfg.board)
    if problem is not None:
        warnings.warn(problem, FewViewsWarning, stacklevel=2)
    with atomic_directory(s.out, overwrite=s.overwrite) as tmp:
        write_recording_files(recording, tmp)
        if s.images:
            write_images(recording, tmp)
    return s.out


def record_static_imu(s: RecordSettings) -> Path:
    """The drawn sensor's IMU lying still for ``static_duration``, as an IMU-only EuRoC folder (``vical-imu-noise``'s
    input; ``imu0/sensor.yaml`` holds the true noise). Closed form (``vical.sim.imu.static_imu``), no arm, no
    camera: hours of data in seconds, generated and written a minute at a time."""
    sampling = draw_product(s.sampling, s.seed).sampling
    truth = sample_sensor(sampling, np.random.default_rng(s.seed), asymmetric=s.asymmetric_distortion)
    noise = truth.imu_noise
    chunks = static_imu(truth, np.random.default_rng([s.seed, 1]), s.static_duration)
    minutes = int(np.ceil(s.static_duration / STATIC_CHUNK_S))
    shown = tqdm(chunks, desc=APP, total=minutes, unit="min", disable=not s.progress)
    comment = f"written by vical-record mode=static_imu seed={s.seed}: the IMU at rest, its true noise below"
    return write_euroc_imu(s.out, shown, noise, noise.rate_hz, comment, overwrite=s.overwrite)


# An absolute path: the console script imports this module, and Hydra would read a relative
# config_path as a Python package ("conf") that does not exist.
CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")


@hydra.main(config_path=CONF_DIR, config_name="record", version_base="1.3")
def hydra_main(cfg: DictConfig) -> None:
    task_begins()
    try:
        with write_faults_in_one_line(APP, "out=", cfg.out):
            out = record(cfg)
    except USER_ERRORS as err:
        fail(APP, err)
    print(f"recording written to {out}")


def main() -> None:
    """Console entry point: the settings, and Hydra's own override errors, are checked before Hydra runs."""
    check_then_run(APP, CONF_DIR, "record", check_settings, hydra_main, USER_ERRORS)


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command(APP, main)

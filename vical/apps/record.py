"""``vical-record``: move the simulated Panda through pose steps and write a recording (``conf/record.yaml``).

The sensor is drawn from the ``sensor`` group with the run's seed (the distortion centre only
where ``task.asymmetric_distortion`` says so); the arm executes ``steps`` in MuJoCo physics while
the IMU and camera record; the result is saved with ``vical.io.save_recording`` (atomically), and
with ``images=true`` the rendered frames are also written as ``<out>/images/<t_ns>.png``.
"""

from __future__ import annotations

from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from vical.calib.aprilgrid import detect_aprilgrid
from vical.calib.detection import detect_checkerboard
from vical.config import ConfigError, require
from vical.data import Recording
from vical.geometry import step_pose
from vical.io.atomic import atomic_directory
from vical.io.images import write_png
from vical.io.recording import save_recording
from vical.sim import PandaSim, SimConfig
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import SensorSampling, sample_sensor


def parse_steps(steps) -> np.ndarray:
    """``steps`` as an (S, 6) float array; ``ConfigError`` naming the bad entry otherwise."""
    require(
        steps is not None and len(steps) > 0, "steps", "a non-empty list of [dx, dy, dz, droll, dpitch, dyaw]", steps
    )
    parsed = []
    for i, step in enumerate(steps):
        try:
            row = np.asarray(list(step), dtype=float)
        except (TypeError, ValueError):
            raise ConfigError(f"steps[{i}] must be 6 numbers [dx, dy, dz, droll, dpitch, dyaw], got {step!r}") from None
        require(row.shape == (6,) and bool(np.all(np.isfinite(row))), f"steps[{i}]", "6 finite numbers", list(step))
        parsed.append(row)
    return np.array(parsed)


def write_images(recording: Recording, folder: Path) -> None:
    """Write every frame's image as ``<folder>/<t_ns>.png`` (all or nothing)."""
    with atomic_directory(folder) as tmp:
        for t, image in zip(recording.frames.t, recording.frames.images, strict=True):
            write_png(tmp / f"{int(t)}.png", image)


def record(cfg: DictConfig) -> Path:
    """Run the motion of ``cfg`` with a sampled sensor and write the recording; return its directory."""
    steps = parse_steps(OmegaConf.to_container(cfg.steps, resolve=True))
    sampling = SensorSampling.from_config(OmegaConf.to_container(cfg.sensor, resolve=True))
    out = Path(str(cfg.out))
    if out.exists() and not cfg.overwrite:
        raise FileExistsError(f"out={out} already exists; choose another directory or pass overwrite=true")
    sim = PandaSim(SimConfig.from_mapping(cfg.sim))
    rng = np.random.default_rng(int(cfg.seed))
    truth = sample_sensor(sampling, rng, asymmetric=bool(cfg.task.asymmetric_distortion))
    detector = detect_aprilgrid if sim.cfg.board.kind == "aprilgrid" else detect_checkerboard
    detector = detector if sampling.backend == "render" else None
    size = tuple(int(s) for s in cfg.render_size)
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling, detector, bool(cfg.images), render_size=size)
    try:
        recorder.start(truth, rng)
        for step in tqdm(steps, desc="vical-record", unit="step", disable=not cfg.progress):
            T_goal = step_pose(sim.ee_pose(), step[:3], step[3:])
            recorder.add_motion(sim.move_to(T_goal, on_step=recorder.on_step, settle_time=float(cfg.settle_time)))
        metadata = {"seed": int(cfg.seed), "config": OmegaConf.to_container(cfg, resolve=True)}
        recording = recorder.recording(metadata)
    finally:
        recorder.close()
    save_recording(recording, out, overwrite=bool(cfg.overwrite))
    if cfg.images:
        write_images(recording, out / "images")
    return out


# An absolute path: the console script imports this module, and Hydra would read a relative
# config_path as a Python package ("conf") that does not exist.
CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")


@hydra.main(config_path=CONF_DIR, config_name="record", version_base="1.3")
def main(cfg: DictConfig) -> None:
    out = record(cfg)
    print(f"recording written to {out}")


if __name__ == "__main__":
    main()

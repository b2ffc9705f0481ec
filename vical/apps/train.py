"""``vical-train``: the Hydra entry point of :func:`vical.rl.trainer.train` (config: ``conf/train.yaml``).

``vical-train resume=<run dir>`` continues a run from its checkpoint with the run's saved config; other
``key=value`` overrides on the command line apply on top (only the length of the run and the cadence of
logging, evaluation and checkpoints may differ from the checkpoint's config: ``RESUMABLE_KEYS``).
"""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from vical.config import ConfigError
from vical.rl.trainer import train

# An absolute path: a relative config_path would resolve against the installed package when the console
# script runs from another directory.
CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")

# hydra.run.dir of a resumed run is the run being resumed, so no second output directory appears.
OmegaConf.register_new_resolver("vical_resume_or", lambda resume, fresh: resume or fresh, replace=True)


def resumed_config(resume: str, overrides: list[str]) -> DictConfig:
    """The saved config of the run at ``resume`` with the command line's ``key=value`` overrides applied."""
    saved = Path(resume) / "config.yaml"
    if not saved.is_file():
        raise ConfigError(f"resume must be a run directory of vical-train containing config.yaml, got {resume!r}")
    cfg = OmegaConf.load(saved)
    dotlist = [o.lstrip("+") for o in overrides if not o.lstrip("+").startswith("resume=")]
    cfg = OmegaConf.merge(cfg, OmegaConf.from_dotlist(dotlist))
    cfg.resume = resume
    cfg.run_dir = resume
    return cfg


@hydra.main(config_path=CONF_DIR, config_name="train", version_base="1.3")
def main(cfg: DictConfig) -> None:
    if cfg.resume:
        cfg = resumed_config(str(cfg.resume), list(HydraConfig.get().overrides.task))
    result = train(cfg)
    print(f"trained {result.steps} steps, {result.episodes} episodes; run directory: {result.run_dir}")


if __name__ == "__main__":
    main()

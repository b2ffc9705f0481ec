"""``vical-train``: the Hydra entry point of :func:`vical.rl.trainer.train` (config: ``conf/train.yaml``).

``vical-train resume=<run dir>`` continues a run from its checkpoint with the run's saved config; other
``key=value`` overrides on the command line apply on top (only the length of the run and the cadence of
logging, evaluation and checkpoints may differ from the checkpoint's config: ``RESUMABLE_KEYS``). On
resume, overrides may only change keys the saved config has: group selections (``agent=...``), additions
(``+key=...``) and deletions (``~key``) are refused by name.

User-facing errors (a bad config value, an incompatible checkpoint, a missing run directory, diverged
training) print one line ``vical-train: error: ...`` and exit with status 2, as ``vical-calibrate`` does.
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import Override, OverrideType
from hydra.errors import InstantiationException
from omegaconf import DictConfig, OmegaConf

from vical.apps.cli import check_launcher, fail, override_value
from vical.config import ConfigError
from vical.rl.checkpoint import IncompatibleCheckpointError
from vical.rl.trainer import TrainingDivergedError, train

# An absolute path: a relative config_path would resolve against the installed package when the console
# script runs from another directory.
CONF_DIR = str(Path(__file__).resolve().parents[2] / "conf")

# Errors whose message tells the user what to fix: printed as one line, no traceback.
USER_ERRORS = (
    ConfigError,
    IncompatibleCheckpointError,
    FileNotFoundError,
    TrainingDivergedError,
    InstantiationException,  # the env's _target_ could not be built (bad id, bad arguments)
)
APP = "vical-train"

_ABSENT = object()


def _resume_or(resume: str | None, fresh: str) -> str:
    """hydra.run.dir: the run being resumed (so no second output directory appears), else a fresh one."""
    if resume:
        check_resume_dir(resume)  # never let Hydra create a directory for a mistyped resume path
        return resume
    return fresh


OmegaConf.register_new_resolver("vical_resume_or", _resume_or, replace=True)


def check_resume_dir(resume: str) -> Path:
    """``resume`` as a Path; ``ConfigError`` unless it is a run directory of vical-train (holds config.yaml)."""
    path = Path(resume)
    if not (path / "config.yaml").is_file():
        what = "does not exist" if not path.exists() else "has no config.yaml"
        raise ConfigError(f"resume must be a run directory of vical-train containing config.yaml; {resume!r} {what}")
    return path


def resumed_config(resume: str, overrides: list[str]) -> DictConfig:
    """The saved config of the run at ``resume`` with the command line's ``key=value`` overrides applied.

    Only plain ``key=value`` changes of keys present in the saved config are accepted; anything else
    (group selections, ``+``/``++`` additions, ``~`` deletions, unknown keys) raises ``ConfigError`` naming
    each offending override.
    """
    cfg = OmegaConf.load(check_resume_dir(resume) / "config.yaml")
    parsed = [o for o in OverridesParser.create().parse_overrides(overrides) if o.key_or_group != "resume"]
    refused = [f"{o.input_line} ({why})" for o in parsed if (why := _refusal(o, cfg))]
    if refused:
        listing = "\n  ".join(refused)
        raise ConfigError(
            f"on resume the run's saved config ({Path(resume) / 'config.yaml'}) is used; these overrides cannot "
            f"apply to it:\n  {listing}\nOnly key=value changes of existing keys are accepted "
            "(e.g. train.total_steps=20000); start a new run to change anything else."
        )
    for o in parsed:
        OmegaConf.update(cfg, o.key_or_group, o.value(), merge=False)
    cfg.resume = resume
    cfg.run_dir = resume
    return cfg


def _refusal(override: Override, saved: DictConfig) -> str | None:
    """Why ``override`` cannot apply to a resumed run's saved config, or None when it can."""
    key = override.key_or_group
    if override.is_sweep_override():
        return "a sweep"
    if override.type == OverrideType.DEL:
        return "a deletion: the saved config is complete"
    if override.type in (OverrideType.ADD, OverrideType.FORCE_ADD):
        return "an addition: only keys of the saved config may change"
    if override.package is not None or (Path(CONF_DIR) / key).is_dir():
        return f"a config group selection: the saved config already fixes {key}"
    value = OmegaConf.select(saved, key, default=_ABSENT)
    if value is _ABSENT:
        return f"unknown key {key!r}"
    if isinstance(value, DictConfig):
        return f"{key} is a section, set its keys one by one ({key}.<key>=...)"
    return None


@hydra.main(config_path=CONF_DIR, config_name="train", version_base="1.3")
def hydra_main(cfg: DictConfig) -> None:
    try:
        if cfg.resume:
            cfg = resumed_config(str(cfg.resume), list(HydraConfig.get().overrides.task))
        result = train(cfg)
    except USER_ERRORS as err:
        fail(APP, err)
    print(f"trained {result.steps} steps, {result.episodes} episodes; run directory: {result.run_dir}")


def main() -> None:
    """Console entry point: check a ``resume=`` path and the launcher plugin before Hydra starts, then run."""
    resume = override_value(sys.argv[1:], "resume")
    try:
        check_launcher(sys.argv[1:])
        if resume is not None:
            check_resume_dir(resume)
    except ConfigError as err:
        fail(APP, err)
    hydra_main()


if __name__ == "__main__":
    main()

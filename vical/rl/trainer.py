"""``vical-train``'s training: :func:`train` runs a ``Trainer`` (one env, ``vical.rl.single_env_trainer``) or, with
``train.num_envs > 1``, a ``VectorTrainer`` (env workers, ``vical.rl.vector_trainer``).

The names of a run that lived here before are imported here too, for old imports: the settings
(``vical.rl.run_settings``), the env and its action box (``vical.rl.envs``), the run directory's files and
resume status (``vical.rl.checkpoint``) and the loop (``vical.rl.single_env_trainer``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from omegaconf import DictConfig, OmegaConf

from vical.rl.checkpoint import AGENT, CHECKPOINT, LAST_GOOD, checkpoint_step, resume_status
from vical.rl.envs import BoxActions, make_env
from vical.rl.run_settings import MAX_POLICY_LAG, RunSettings, TrainConfig, parse_settings
from vical.rl.single_env_trainer import EVAL_SEED_OFFSET, Episode, Trainer, TrainingDivergedError, TrainResult
from vical.rl.vector_trainer import VectorTrainer

__all__ = [
    "AGENT",
    "CHECKPOINT",
    "EVAL_SEED_OFFSET",
    "LAST_GOOD",
    "MAX_POLICY_LAG",
    "BoxActions",
    "Episode",
    "RunSettings",
    "TrainConfig",
    "TrainResult",
    "Trainer",
    "TrainingDivergedError",
    "VectorTrainer",
    "checkpoint_step",
    "make_env",
    "parse_settings",
    "resume_status",
    "train",
]


def train(cfg: Mapping[str, Any]) -> TrainResult:
    """Train SAC on the configured env (a Hydra ``DictConfig`` or a plain mapping; see ``conf/train.yaml``).

    ``train.num_envs > 1`` collects experience from that many env workers (``vical.rl.vector_trainer``).
    """
    raw = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
    if parse_settings(raw).train.num_envs > 1:
        return VectorTrainer(raw).run()
    return Trainer(raw).run()

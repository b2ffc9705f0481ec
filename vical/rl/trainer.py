"""``vical-train``'s training: :func:`train` runs a ``Trainer`` (one env, ``vical.rl.single_env_trainer``) or, with
``train.num_envs > 1``, a ``VectorTrainer`` (env workers, ``vical.rl.vector_trainer``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from omegaconf import DictConfig, OmegaConf

from vical.rl.run_settings import parse_settings
from vical.rl.single_env_trainer import Trainer, TrainResult
from vical.rl.vector_trainer import VectorTrainer


def train(cfg: Mapping[str, Any]) -> TrainResult:
    """Train SAC on the configured env (a Hydra ``DictConfig`` or a plain mapping; see ``conf/train.yaml``).

    ``train.num_envs > 1`` collects experience from that many env workers (``vical.rl.vector_trainer``).
    """
    raw = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
    if parse_settings(raw).train.num_envs > 1:
        return VectorTrainer(raw).run()
    return Trainer(raw).run()

"""Checkpoint files (written atomically with :mod:`vical.io.atomic`) and checkpoint config compatibility."""

from __future__ import annotations

import pickle
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from vical.io.atomic import atomic_file

# Settings a resumed run may change: none of them touches the training's random streams or arithmetic
# (evaluation uses its own env and deterministic actions; logging, plots and checkpoints only read state).
RESUMABLE_KEYS = frozenset(
    {
        "resume",
        "run_dir",
        "train.total_steps",
        "train.progress",
        "train.log_every",
        "train.eval_every",
        "train.eval_episodes",
        "train.eval_max_episode_steps",
        "train.plot_every_episodes",
        "train.checkpoint_every",
        "train.info_prefixes",
        # Where the env workers run changes no number of the run (train.num_envs does, and is not here).
        "parallel.workers",
        "parallel.backend",
        "parallel.ray_address",
    }
)


class IncompatibleCheckpointError(ValueError):
    """A checkpoint written under a config that differs from the current one in a setting that matters."""


class UnreadableCheckpointError(ValueError):
    """A checkpoint file that is truncated, corrupt or not a checkpoint (vical writes them atomically: a damaged
    copy, a full disk elsewhere, or another program's file)."""


# What torch.load raises for a file that is not a complete checkpoint (it has no exception type of its own).
_UNREADABLE = (RuntimeError, EOFError, KeyError, ValueError, pickle.UnpicklingError, OSError)


def save_checkpoint(state: dict, path: str | Path) -> None:
    """``torch.save`` ``state`` to ``path`` atomically: a crash leaves the old file or the complete new one."""
    with atomic_file(path) as tmp:
        torch.save(state, tmp)


def load_checkpoint(path: str | Path, mmap: bool = False) -> dict:
    """Load a checkpoint written by :func:`save_checkpoint` (tensors, numbers, strings and containers only).

    ``mmap``: map the tensors from the file instead of reading them (cheap when only the counters are needed).
    Raises ``UnreadableCheckpointError`` for a file that is not a complete checkpoint.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint at {path}: resume=<run dir> must name a run directory of vical-train")
    try:
        return torch.load(path, map_location="cpu", weights_only=True, mmap=mmap)
    except _UNREADABLE as exc:
        reason = str(exc).split(". ")[0] or type(exc).__name__
        raise UnreadableCheckpointError(
            f"{path} cannot be read as a checkpoint (truncated or corrupt: {reason}); it cannot be resumed from: "
            "restore it from a copy or start a new run"
        ) from None


def flatten(cfg: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}} -> {"a.b": 1}``; lists stay values."""
    flat: dict[str, Any] = {}
    for key, value in cfg.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten(value, f"{name}."))
        else:
            flat[name] = value
    return flat


# Settings added after runs were written with the value those runs had: such a run still resumes.
ADDED_KEYS = {"train.num_envs": 1, "train.policy_lag": 4}


def config_differences(saved: Mapping[str, Any], current: Mapping[str, Any]) -> list[str]:
    """Lines ``key: saved -> current`` for every setting outside ``RESUMABLE_KEYS`` that differs."""
    old, new = {**ADDED_KEYS, **flatten(saved)}, flatten(current)
    keys = sorted((set(old) | set(new)) - RESUMABLE_KEYS)
    missing = "<absent>"
    return [
        f"{k}: {old.get(k, missing)!r} (checkpoint) vs {new.get(k, missing)!r} (now)"
        for k in keys
        if old.get(k, missing) != new.get(k, missing)
    ]


def require_compatible(saved: Mapping[str, Any], current: Mapping[str, Any], path: str | Path) -> None:
    """Refuse to resume from ``path`` when its config differs from ``current``, listing each differing key."""
    diffs = config_differences(saved, current)
    if diffs:
        listing = "\n  ".join(diffs)
        raise IncompatibleCheckpointError(
            f"checkpoint {path} was written with a different config:\n  {listing}\n"
            "Resume with the run's own config (vical-train resume=<run dir> loads it; only "
            f"{sorted(RESUMABLE_KEYS - {'resume', 'run_dir'})} may change) or start a new run."
        )

"""Checkpoint files (written atomically with :mod:`vical.io.atomic`), checkpoint config compatibility, and the files of
a run directory: whether a run can resume, and from where."""

from __future__ import annotations

import io
import pickle
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from vical.config_checks import ConfigError
from vical.io.atomic import atomic_file

CHECKPOINT = "checkpoint.pt"  # latest episode-boundary checkpoint: what resume=<run dir> continues from
LAST_GOOD = "last_good.pt"  # state just before a non-finite loss/observation, for inspection
AGENT = "agent.pt"  # final networks + agent config, for evaluation and deployment

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
    """``torch.save`` ``state`` to ``path`` atomically: a crash leaves the old file or the complete new one.

    Serialised in memory first, then written: torch's own file writer turns a full disk into a ``RuntimeError``
    ("unexpected pos"), where Python's write raises the ``OSError`` (ENOSPC, EROFS) that the commands report."""
    data = io.BytesIO()
    torch.save(state, data)
    with atomic_file(path) as tmp:
        tmp.write_bytes(data.getbuffer())


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
ADDED_KEYS = {"train.num_envs": 1, "train.policy_lag": 4, "train.distill": None}


def config_differences(saved: Mapping[str, Any], current: Mapping[str, Any]) -> list[str]:
    """Lines ``key: saved -> current`` for every setting outside ``RESUMABLE_KEYS`` that differs."""
    saved_flat, new = flatten(saved), flatten(current)
    # an added key's value fills in only where the run has neither the key nor settings under it (train.distill.*)
    added = {k: v for k, v in ADDED_KEYS.items() if not any(s == k or s.startswith(k + ".") for s in saved_flat)}
    old = {**added, **saved_flat}
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


def require_reachable(total_steps: int, step: int, run_dir: Path) -> None:
    """Refuse a ``total_steps`` below the checkpoint's ``step``: resuming would overwrite later work with earlier."""
    if total_steps < step:
        raise ConfigError(
            f"train.total_steps={total_steps} is below step {step} of the checkpoint {run_dir / CHECKPOINT}: the run "
            f"is past it already; resume with train.total_steps >= {step}"
        )


def checkpoint_step(run_dir: str | Path) -> int | None:
    """The step of the run's checkpoint, None when it has none (its tensors are mapped, not read)."""
    path = Path(run_dir) / CHECKPOINT
    return int(load_checkpoint(path, mmap=True)["counters"]["step"]) if path.is_file() else None


def resume_status(run_dir: str | Path, total_steps: int) -> str | None:
    """Whether the run at ``run_dir`` can go on to ``total_steps``: None when it can (from its checkpoint), a
    message when it is complete at that length already (nothing to do).

    A finished run (``agent.pt`` written at the end, no later checkpoint) asked for more steps goes on from
    its last checkpoint: the steps after it are run again, identically, so the result equals a run of
    ``total_steps`` from the start.

    Raises:
        ConfigError: the run would be shortened, or it has no checkpoint to go on from.
    """
    run = Path(run_dir)
    checkpoint = checkpoint_step(run)
    agent = run / AGENT
    finished = int(load_checkpoint(agent, mmap=True)["config"]["train"]["total_steps"]) if agent.is_file() else None
    if finished is not None and (checkpoint is None or checkpoint <= finished):
        if total_steps == finished:
            return f"run {run} is complete: it trained {finished} steps and wrote {agent}; nothing to do"
        if total_steps < finished:
            raise ConfigError(
                f"train.total_steps={total_steps} is below the {finished} steps run {run} finished with: a run cannot "
                f"be shortened (its agent is {agent}); start a new run for a shorter one"
            )
        if checkpoint is None:
            raise ConfigError(
                f"run {run} finished at {finished} steps without a checkpoint to go on from (train.checkpoint_every); "
                f"start a new run with train.total_steps={total_steps}"
            )
        return None
    if checkpoint is None:
        raise ConfigError(
            f"run {run} has no checkpoint yet (it stopped before its first one, at the first episode end after "
            "train.checkpoint_every steps): start it again"
        )
    require_reachable(total_steps, checkpoint, run)
    return None

"""The validated root config of ``vical-train`` (``conf/train.yaml``): the loop's settings and the run's.

``parse_settings`` checks every value and fills in the defaults; out-of-range or unknown settings raise
``ConfigError`` naming the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from vical.config_checks import from_mapping, require, require_range
from vical.parallel import MAX_WORKERS, ParallelConfig
from vical.rl.distill import DistillConfig
from vical.rl.sac import SACConfig

# A policy version is kept per round of lag (a copy of the policy network): beyond this, memory grows for no gain
# (4 rounds already keep 2 workers busy, docs/scaling.md).
MAX_POLICY_LAG = 64


@dataclass
class TrainConfig:
    """Loop settings (steps count env transitions)."""

    total_steps: int = 10_000
    warmup_steps: int = 1_000  # no updates before this many steps: uniform random actions (or the demonstrator's)
    updates_per_step: int = 1  # gradient updates per collected transition (num_envs of them per round of steps)
    num_envs: int = 1  # environments, each in a worker process when > 1 (vical.rl.vector)
    policy_lag: int = 4  # with num_envs > 1: rounds between the network that samples an action and the newest
    buffer_size: int = 1_000_000
    eval_every: int = 2_000
    eval_episodes: int = 5
    eval_max_episode_steps: int = 10_000  # ends an evaluation episode of an env without a time limit
    log_every: int = 100
    plot_every_episodes: int = 10
    checkpoint_every: int = 1_000
    progress: bool = True
    info_prefixes: list[str] = field(default_factory=lambda: ["calib/", "coverage/", "reward/", "information/"])
    # ``_target_`` + arguments of a demonstrator (``reset(env, rng)``, ``act(obs, env)`` -> an env action, as a
    # collection policy): the warm-up's actions are its instead of uniform random ones (``vical.rl.demonstrations``)
    demonstrator: dict | None = None
    clone_updates: int = 0  # updates after the warm-up that clone the demonstrations before SAC's own updates
    # DAgger rounds before SAC's steps, the demonstrator labelling the policy's own states (``vical.rl.distill``);
    # with it ``total_steps`` counts SAC's steps after the distillation (0: the distilled policy is the agent)
    distill: DistillConfig | None = None

    def __post_init__(self) -> None:
        _require_int("train.total_steps", self.total_steps, 0 if self.distill is not None else 1)
        for name in ("updates_per_step", "buffer_size", "eval_episodes", "eval_max_episode_steps"):
            _require_int(f"train.{name}", getattr(self, name), 1)
        n = self.num_envs
        ok = isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_WORKERS
        require(ok, "train.num_envs", f"an integer from 1 to {MAX_WORKERS} (env worker processes)", n)
        _require_int("train.policy_lag", self.policy_lag, 1)
        require(
            self.policy_lag <= MAX_POLICY_LAG, "train.policy_lag", f"at most {MAX_POLICY_LAG} rounds", self.policy_lag
        )
        for name in ("warmup_steps", "eval_every", "log_every", "plot_every_episodes", "checkpoint_every"):
            _require_int(f"train.{name}", getattr(self, name), 0)
        self.info_prefixes = list(self.info_prefixes)
        self._check_demonstrations()

    def _check_demonstrations(self) -> None:
        d = self.demonstrator
        ok = d is None or (isinstance(d, Mapping) and "_target_" in d)
        require(ok, "train.demonstrator", "null or a mapping with a _target_ (a demonstrator's factory)", d)
        self.demonstrator = None if d is None else dict(d)
        _require_int("train.clone_updates", self.clone_updates, 0)
        if self.clone_updates:
            require(self.demonstrator is not None, "train.clone_updates",
                    "0 without train.demonstrator (there is nothing to clone)", self.clone_updates)  # fmt: skip
            require(self.warmup_steps >= 1, "train.warmup_steps",
                    "at least 1 with train.clone_updates (the demonstrations are the warm-up's steps)",
                    self.warmup_steps)  # fmt: skip
        if self.distill is not None:
            teacher = "null without train.demonstrator (the teacher whose actions it learns)"
            require(self.demonstrator is not None, "train.distill", teacher, asdict(self.distill))
            itself = "0 with train.distill (the distillation fits the teacher's labels itself)"
            require(not self.clone_updates, "train.clone_updates", itself, self.clone_updates)


def _require_int(key: str, value: Any, low: int) -> None:
    require(isinstance(value, int) and not isinstance(value, bool), key, "an integer", value)
    require_range(key, value, low)


@dataclass
class RunSettings:
    """The validated root config of ``vical-train`` (``env`` stays a mapping for ``instantiate``)."""

    seed: int
    torch_threads: int
    run_dir: Path
    resume: Path | None
    agent: SACConfig
    train: TrainConfig
    env: dict
    parallel: ParallelConfig = field(default_factory=ParallelConfig)

    def effective_config(self) -> dict:
        """Every setting with defaults filled in, as plain containers (the run's config.yaml)."""
        return {
            "seed": self.seed,
            "torch_threads": self.torch_threads,
            "run_dir": str(self.run_dir),
            "resume": None if self.resume is None else str(self.resume),
            "agent": asdict(self.agent),
            "train": asdict(self.train),
            "env": self.env,
            "parallel": asdict(self.parallel),
        }


def parse_settings(cfg: Mapping[str, Any]) -> RunSettings:
    """Validate the root config; out-of-range or unknown settings raise ``ConfigError`` naming the key."""
    _require_int("seed", cfg.get("seed"), 0)
    _require_int("torch_threads", cfg.get("torch_threads"), 1)
    env = cfg.get("env")
    require(isinstance(env, Mapping) and "_target_" in env, "env", "a mapping with a _target_ (env factory)", env)
    resume = cfg.get("resume")
    run_dir = resume if resume else cfg.get("run_dir")
    require(bool(run_dir), "run_dir", "a directory path (or set resume=<run dir>)", run_dir)
    return RunSettings(
        seed=cfg["seed"],
        torch_threads=cfg["torch_threads"],
        run_dir=Path(run_dir),
        resume=Path(resume) if resume else None,
        agent=from_mapping(SACConfig, cfg.get("agent", {}), "agent"),
        train=from_mapping(TrainConfig, cfg.get("train", {}), "train"),
        env=dict(env),
        parallel=ParallelConfig.from_config(cfg.get("parallel")),
    )

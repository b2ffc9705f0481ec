"""The frozen yardsticks: a fingerprint of their baselines, workspace, sensors and protocol.

The yardsticks (``conf/experiment/yardstick_*.yaml``: error at equal effort; ``time_to_tolerance_*.yaml``: time
until the shared stopping rule, docs/results.md) are frozen before any policy is tuned against them: a later change
of a baseline must be visible. ``fingerprint`` hashes, from the
composed evaluation config, (1) every baseline's resolved config and the motion it generates (the
expert's waypoints, the fitted loop's coefficients, the random loop and random actions drawn from a
fixed seed), (2) the environment the baselines run in (workspace, board, start pose, simulator,
sensor distributions, task, step limits, coverage thresholds) and (3) the protocol (sensors,
budgets, reference). The environment's reward and its own calibration switches are left out: no
baseline reads the reward, and the evaluation sets the switches itself, so a new reward for a
learned policy leaves the yardstick as it is. docs/results.md records the hashes;
``tests/test_yardstick.py`` recomputes them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from vical.evaluation.harness import PolicySpec, instantiate_policy
from vical.policies.base import Policy
from vical.policies.expert import ExpertPolicy
from vical.policies.fourier import FourierTrajectory, FourierTrajectoryPolicy
from vical.policies.greedy import GreedyInformationPolicy, candidate_actions
from vical.policies.random_policy import RandomMovingPolicy

PROTOCOL_KEYS = ("episodes", "seed", "budgets", "reference", "paper_protocol", "policies")
STOP_KEYS = ("stop",)  # the shared stopping rule's settings, where the yardstick has one (time to the tolerances)
DRAW_SEED = 0  # the seed of the random loop and actions whose values enter the fingerprint
# Env keys that cannot change a baseline's episode: the reward and the learner's discount at the step limit
# (no baseline reads them: the greedy planner prices with its learned run's reward, hashed with it) and the
# env's own calibration and termination switches (vical.evaluation.harness.build_env sets them per policy).
NOT_EPISODE_KEYS = (
    "reward",
    "step_limit_final",
    "calibrate_on_termination",
    "calibrate_on_truncation",
    "terminate_on_coverage",
)


def _digest(value: Any) -> str:
    text = json.dumps(value, sort_keys=True, separators=(",", ":"), default=_plain)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return np.round(np.asarray(value, dtype=float), 9).tolist()
    raise TypeError(f"cannot fingerprint {type(value).__name__}")


def _motion(policy: Policy, action_scale: np.ndarray) -> dict[str, Any]:
    """What a baseline will do, as numbers: waypoints, loop coefficients or a seeded draw of actions."""
    rng = np.random.default_rng(DRAW_SEED)
    if isinstance(policy, ExpertPolicy):
        return {"fractions": policy.fractions, "max_steps": policy.max_steps}
    if isinstance(policy, FourierTrajectoryPolicy):
        trajectory = FourierTrajectory.random(rng) if policy.redraw else policy.trajectory
        return {"coefficients": trajectory.coefficients, "waypoints": policy.num_waypoints, "redraw": policy.redraw}
    if isinstance(policy, RandomMovingPolicy):
        actions = rng.uniform(-action_scale, action_scale, (20, 6))
        return {"actions": actions, "max_steps": policy.max_steps, "stop_at_coverage": policy.stop_at_coverage}
    if isinstance(policy, GreedyInformationPolicy):  # the state and prices it plans with, its first candidates
        candidates = candidate_actions(action_scale, policy.samples, rng)
        settings = {**policy.env_settings, "reward": dataclasses.asdict(policy.reward)}
        return {"settings": settings, "max_steps": policy.max_steps, "candidates": candidates}
    raise TypeError(f"the yardstick knows no baseline of type {type(policy).__name__}")


def fingerprint(cfg: Mapping[str, Any]) -> dict[str, str]:
    """Hashes of a composed, resolved ``vical-evaluate`` config of the yardstick (16 hex digits each).

    Args:
        cfg: with ``policy_configs`` (name -> resolved policy config, in ``policies`` order), ``env``
            (the resolved env config) and the protocol keys (``PROTOCOL_KEYS``); a yardstick whose policies all
            stop by the information state adds ``stop``: the rule's resolved settings (its tolerances, confidence,
            goal groups and step limit), part of its protocol.

    Returns:
        ``{"baselines": ..., "environment": ..., "protocol": ..., "<policy name>": ..., "yardstick": ...}``;
        ``yardstick`` hashes the three parts.
    """
    scale = np.asarray(cfg["env"]["action_scale"], dtype=float)
    per_policy = {}
    for name, config in cfg["policy_configs"].items():
        spec = PolicySpec.from_config(config)
        motions = {
            task: _motion(instantiate_policy(getattr(spec, task), spec.name), scale)
            for task in ("intrinsic", "extrinsic", "joint")
            if getattr(spec, task) is not None
        }
        per_policy[name] = _digest({"config": config, "motion": motions})
    parts = {
        "baselines": _digest(per_policy),
        "environment": _digest({k: v for k, v in cfg["env"].items() if k not in NOT_EPISODE_KEYS}),
        "protocol": _digest({key: cfg[key] for key in (*PROTOCOL_KEYS, *STOP_KEYS) if key in cfg}),
    }
    return {**parts, **per_policy, "yardstick": _digest(parts)}

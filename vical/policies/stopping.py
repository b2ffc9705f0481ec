"""When a policy's episode ends: by its own rule (``stop=policy``) or by the information state (``stop=information``).

Each policy has its own rule: a learned policy of the information state stops when it predicts every
parameter group within its tolerance; the random moving policy at the coverage; a fixed trajectory at its
last waypoint. With their own rules the policies differ in when they stop as much as in how they move.
``stop=information`` gives every policy whose actions do not read the env's state (the baselines) the
learned policy's rule: the same information state, tolerances, confidence and goal groups, read from the
learned run (``stop.run_dir``; by default the policy shipped for the workspace). Its motion is unchanged;
the episode ends at the first step after which every group is predicted within tolerance, at the policy's
own end (a trajectory's last waypoint) or at its step limit (the policy's own, else the learned run's),
whichever comes first. A learned policy of the information state keeps its own rule; one trained on
another state is refused (its actions need the state it was trained on).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from vical.config_checks import ConfigError, from_mapping, require
from vical.env.calibration import CalibrationEnv
from vical.policies.base import Policy
from vical.policies.learned import DEFAULT_WORKSPACE, carried_settings, load_run, shipped_policy_dir

RULES = ("policy", "information")


@dataclass(frozen=True)
class StopRule:
    """The ``stop`` config group (``conf/stop/``).

    Attributes:
        rule: ``policy`` (each policy's own) or ``information`` (the information state's, for every baseline).
        run_dir: the learned run (``vical-train env=information``) whose information settings the rule uses;
            None: the policy shipped for ``workspace``.
        workspace: the workspace the policies run in (the shipped policy is chosen by it).
        max_steps: the step limit of every policy the rule stops that has none of its own, and of the greedy
            planner; None: the learned run's.
        horizon_s: the time-to-tolerance summary's common horizon [s]: a run that has not stopped by then counts
            at it, whenever its own limit ended it (``vical.evaluation.time_to_tolerance``); None: each run at its
            own end.
        out_of_reach: with a horizon, a run also stops when the information state's reachability forecast calls
            the goal out of reach within it (``vical.env.reachability``); it counts at the horizon.
        verify_s: [s] a run stopped as out of reach goes on to this much recording, to check the verdict (did a
            longer run reach the goal?); None: it ends at the verdict.
    """

    rule: str = "policy"
    run_dir: str | None = None
    workspace: str = DEFAULT_WORKSPACE
    max_steps: int | None = None
    horizon_s: float | None = None
    out_of_reach: bool = True
    verify_s: float | None = None

    def __post_init__(self) -> None:
        require(self.rule in RULES, "stop.rule", f"one of {RULES} (stop=policy or stop=information)", self.rule)
        require(self.run_dir is None or isinstance(self.run_dir, str), "stop.run_dir", "null or a path", self.run_dir)
        steps = self.max_steps
        ok = steps is None or (isinstance(steps, int) and not isinstance(steps, bool) and steps >= 1)
        require(ok, "stop.max_steps", "null or an integer >= 1", steps)
        horizon = self.horizon_s
        ok = horizon is None or (isinstance(horizon, int | float) and not isinstance(horizon, bool) and horizon > 0)
        require(ok, "stop.horizon_s", "null or a time > 0 [s]", horizon)
        require(isinstance(self.out_of_reach, bool), "stop.out_of_reach", "true or false", self.out_of_reach)
        verify = self.verify_s
        number = isinstance(verify, int | float) and not isinstance(verify, bool)
        ok = verify is None or (horizon is not None and number and verify > horizon)
        require(ok, "stop.verify_s", "null or a time beyond stop.horizon_s [s]", verify)

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any] | None) -> StopRule:
        """The rule of a ``stop`` config node (None: each policy's own)."""
        return cls() if cfg is None else from_mapping(cls, cfg, "stop")


def information_settings(rule: StopRule) -> dict[str, Any]:
    """The information state, tolerances, confidence, goal groups and step limit of the rule's learned run (the
    rule's own step limit where it has one)."""
    try:
        settings = learned_information_settings(rule.run_dir, rule.workspace)
    except ConfigError as err:
        raise ConfigError(f"stop=information: {err}") from None
    return settings if rule.max_steps is None else {**settings, "max_steps": rule.max_steps}


def learned_information_settings(run_dir: str | None, workspace: str, key: str = "stop.run_dir") -> dict[str, Any]:
    """The MDP settings (state, information, max_steps) of the learned run ``run_dir`` of the information state
    (None: the policy shipped for ``workspace``); ``ConfigError`` naming the config ``key`` for another state."""
    return carried_settings(information_run(run_dir, workspace, key)[1])


def information_run(run_dir: str | None, workspace: str, key: str) -> tuple[Path, dict[str, Any]]:
    """The ``agent.pt`` and env config of the learned run ``run_dir`` of the information state (None: the policy
    shipped for ``workspace``); ``ConfigError`` naming the config ``key`` for another state."""
    path, state = load_run(run_dir or shipped_policy_dir(workspace))
    env = state["config"]["env"]
    kind = env.get("state", "coverage")
    if kind != "information":
        raise ConfigError(
            f"the information state's rule is read from a learned run of the information state, but {path} was "
            f"trained on the {kind} state: name one with {key}=<a vical-train env=information run>"
        )
    return path, env


class InformationStop(Policy):
    """``policy``'s motion, its episodes ended by the information state (module doc).

    Args:
        policy: a policy whose actions do not read the env's state.
        settings: the learned run's ``state``, ``information`` and ``max_steps`` (``information_settings``).
    """

    stop_at_coverage = True

    def __init__(self, policy: Policy, settings: Mapping[str, Any]) -> None:
        self.policy = policy
        self.name = policy.name
        self.env_settings = MappingProxyType({k: v for k, v in settings.items() if k != "max_steps"})
        self.max_steps = policy.max_steps if policy.max_steps is not None else settings.get("max_steps")

    def check(self, env: CalibrationEnv) -> None:
        self.policy.check(env)

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        self.policy.reset(env, rng)

    @property
    def finished(self) -> bool:
        return self.policy.finished

    def act(self, obs: np.ndarray, env: CalibrationEnv) -> np.ndarray:
        return self.policy.act(obs, env)


def with_stop(policy: Policy, rule: StopRule) -> Policy:
    """``policy`` with the stopping rule ``rule`` (module doc); ``ConfigError`` for a policy that cannot take it."""
    if rule.rule == "policy" or policy.env_settings.get("state") == "information":
        return policy
    if policy.reads_state:
        raise ConfigError(
            f"stop=information: policy {policy.name!r} acts on the env state it was trained on "
            f"({policy.env_settings.get('state', 'coverage')}), not the information state; evaluate it with "
            "stop=policy, or train one on the information state (vical-train env=information)"
        )
    return InformationStop(policy, information_settings(rule))

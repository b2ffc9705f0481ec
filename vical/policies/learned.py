"""The model-free learned policy: the SAC agent that ``vical-train env=calibration`` (or ``env=information``) wrote.

Evaluation uses the deterministic action (the mean ``tanh(mu(s))`` in ``[-1, 1]^6``), mapped onto the
env's action box exactly as training did (``vical.rl.envs.BoxActions``). The run must have trained
on the calibration env (the 24-D coverage state or the 13-D information state, 6 more with each of its
sensor context and axis uncertainty; 6-D action) with the action scale of the env it drives. A policy
of the information state brings its state and stopping rule to the env it is evaluated in
(``Policy.env_settings``): it stops when it predicts every parameter group within its tolerances.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from vical.config_checks import ConfigError, from_mapping
from vical.env.calibration import CalibrationEnv
from vical.env.settings import STATES, RewardWeights, Workspace
from vical.env.state import env_observation_size, observation_size
from vical.policies.base import Policy
from vical.rl.checkpoint import AGENT, load_checkpoint
from vical.rl.envs import BoxActions
from vical.rl.sac import SAC, SACConfig

CALIBRATION_ENV = "vical.env.calibration.CalibrationEnv"
ACT_SIZE = 6
# The shipped agents (agent.pt and config.yaml, package data, so that evaluation runs without training
# first): `+experiment=train_paper_policy` for the paper's tables in the authors' workspace, and the best
# seed of `+experiment=train_information_policy` for the practitioner's workspace (docs/results.md); and for a
# person who holds the sensor (vical-guide), seed 0 of `+experiment=train_person_policy`, the one trained.
PARAMS_DIR = Path(__file__).resolve().parent / "params"
PAPER_POLICY_DIR = PARAMS_DIR / "paper_policy"
INFORMATION_POLICY_DIR = PARAMS_DIR / "information_policy"
PERSON_POLICY_DIR = PARAMS_DIR / "person_policy"
SHIPPED_POLICIES = {"paper": PAPER_POLICY_DIR, "practitioner": INFORMATION_POLICY_DIR}
DEFAULT_WORKSPACE = "practitioner"
TRAIN_HINT = "train one with `vical-train env=information task=<task>` and pass its run directory"
# The MDP settings an information-state policy carries to the env it is evaluated in.
CARRIED_SETTINGS = ("state", "information", "max_steps")


def _policy_dims(model: dict[str, torch.Tensor], path: Path) -> tuple[int, int]:
    """(obs_dim, act_dim) of the policy network in a SAC state dict (its first and last layer)."""
    layers = sorted((int(k.rsplit(".", 1)[1]), v) for k, v in model.items() if k.startswith("policy.mlp.weights."))
    if not layers:
        raise ConfigError(f"{path} holds no SAC policy network; {TRAIN_HINT}")
    first, last = layers[0][1], layers[-1][1]  # (members, fan_out, fan_in)
    return int(first.shape[-1]), int(last.shape[-2]) // 2  # the policy outputs mean and log-std


def _check_run(state: dict[str, Any], path: Path) -> None:
    """Refuse checkpoints that are not a calibration-env agent, naming the file and what to do."""
    if not all(k in state for k in ("model", "agent_config", "config")):
        raise ConfigError(f"{path} is not an agent file written by vical-train (no model/agent_config/config)")
    env = state["config"].get("env", {})
    target = env.get("_target_")
    if target != CALIBRATION_ENV:
        what = f"{target} {env.get('id', '')}".strip()
        raise ConfigError(f"{path} was trained on {what}, not the calibration env; {TRAIN_HINT}")
    obs_dim, act_dim = _policy_dims(state["model"], path)
    kind = env.get("state", "coverage")
    if kind not in STATES:
        raise ConfigError(f"{path} was trained on an env state {kind!r} that vical does not know; {TRAIN_HINT}")
    size = trained_observation_size(env)
    if (obs_dim, act_dim) != (size, ACT_SIZE):
        raise ConfigError(
            f"{path} has a {obs_dim}-D observation / {act_dim}-D action policy; the calibration env its config "
            f"describes ({kind} state) needs {size}-D / {ACT_SIZE}-D; {TRAIN_HINT}"
        )


def trained_observation_size(env: dict[str, Any]) -> int:
    """The observation length of the env a run's ``env`` config describes (runs from before the sensor context and
    the axis uncertainty have neither)."""
    information = env.get("information", {})
    return observation_size(
        env.get("state", "coverage"), bool(information.get("sensor_context")), bool(information.get("axis_uncertainty"))
    )


def load_run(run_dir: str | Path) -> tuple[Path, dict[str, Any]]:
    """``<run_dir>/agent.pt`` and its checkpoint (model, agent and run config); ``ConfigError`` unless it is a
    calibration-env agent written by vical-train."""
    path = Path(run_dir) / AGENT
    if not path.is_file():
        raise ConfigError(
            f"no trained agent at {path}: policy.run_dir must be a finished vical-train run; {TRAIN_HINT}"
        )
    state = load_checkpoint(path)
    _check_run(state, path)
    return path, state


def trained_reward(path: Path, env: dict[str, Any]) -> RewardWeights:
    """The reward weights a learned run trained with (the ``env`` config of its ``agent.pt`` at ``path``): the prices
    a planner on its information state pays, whatever the env it runs in is given."""
    return from_mapping(RewardWeights, env.get("reward", {}), f"{path}: env.reward")


def carried_settings(env: dict[str, Any]) -> dict[str, Any]:
    """The MDP settings (``CARRIED_SETTINGS``) of an information-state run's env config."""
    return {key: env[key] for key in CARRIED_SETTINGS if key in env}


class LearnedPolicy(Policy):
    """Acts with a trained SAC agent's mean action, mapped to env units.

    Args:
        agent: the trained agent (its policy network is used, in eval mode).
        action_scale: (6,) the action scale it was trained with ([m], [rad] x 5).
        workspace: the workspace it was trained in.
        source: the ``agent.pt`` it came from (named in errors).
        name: shown in evaluation tables.
        max_steps: step limit of its episodes (None: the env's ``max_steps``).
    """

    stop_at_coverage = True
    reads_state = True

    def __init__(
        self,
        agent: SAC,
        action_scale: np.ndarray,
        workspace: Workspace,
        source: Path,
        name: str = "model-free learned policy",
        max_steps: int | None = None,
    ) -> None:
        self.agent = agent.eval()
        self.action_scale = np.asarray(action_scale, dtype=float)
        self.workspace = workspace
        self.source = source
        self.name = name
        self.max_steps = max_steps
        self._actions: BoxActions | None = None

    @classmethod
    def from_run(cls, run_dir: str | Path, **kwargs: Any) -> LearnedPolicy:
        """Load ``<run_dir>/agent.pt`` of a ``vical-train env=calibration`` run; ``ConfigError`` otherwise."""
        path, state = load_run(run_dir)
        env = state["config"]["env"]
        kind = env.get("state", "coverage")
        agent = SAC(trained_observation_size(env), ACT_SIZE, SACConfig(**state["agent_config"]), seed=0)
        agent.load_state_dict(state["model"])
        scale = env.get("action_scale", [np.nan] * ACT_SIZE)
        # Runs from before workspaces were named trained in the authors' box (Workspace's defaults).
        workspace = from_mapping(Workspace, env.get("workspace", {}), f"{path}: env.workspace")
        policy = cls(agent, np.asarray(scale, dtype=float), workspace, path, **kwargs)
        if kind == "information":
            policy.env_settings = carried_settings(env)
        return policy

    def check(self, env: CalibrationEnv) -> None:
        """Refuse an env whose state, workspace or action scale differ from the training's."""
        kind = self.env_settings.get("state", "coverage")
        if env.config.state != kind:
            raise ConfigError(
                f"{self.source} was trained on the env's {kind} state, but the env has env.state={env.config.state}; "
                f"evaluate it with env.state={kind} (vical-evaluate brings the training's state by itself)"
            )
        trained_size = _policy_dims(self.agent.state_dict(), self.source)[0]
        s = env.config.information
        if env_observation_size(env.config) != trained_size:
            raise ConfigError(
                f"{self.source} reads a {trained_size}-D state, but the env's has env.information.sensor_context="
                f"{str(s.sensor_context).lower()} and axis_uncertainty={str(s.axis_uncertainty).lower()}; evaluate it "
                "with the training's (vical-evaluate brings it by itself)"
            )
        trained, here = self.workspace, env.config.workspace
        if trained != here:
            raise ConfigError(
                f"{self.source} was trained in workspace {trained.name!r} (frame {trained.frame}, bounds "
                f"{trained.bound.round(4).tolist()}), but the env has workspace {here.name!r} (frame {here.frame}, "
                f"bounds {here.bound.round(4).tolist()}); evaluate it with workspace={trained.name}"
            )
        if not np.allclose(env.config.action_scale, self.action_scale):
            raise ConfigError(
                f"{self.source} was trained with env.action_scale={self.action_scale.tolist()}, but the env has "
                f"{list(env.config.action_scale)}; evaluate with the training's action scale"
            )

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        """Check the env (``check``) and build the [-1, 1] -> env-units map."""
        self.check(env)
        self._actions = BoxActions(env.action_space)

    def act(self, obs: np.ndarray, env: CalibrationEnv) -> np.ndarray:
        """The agent's mean action for ``obs`` (the env's state), in env units (6,)."""
        if self._actions is None:
            raise RuntimeError("LearnedPolicy.act called before reset(env, rng)")
        return self._actions.to_env(self.agent.act(np.asarray(obs, dtype=np.float32), deterministic=True))


def shipped_policy_dir(workspace: str = DEFAULT_WORKSPACE) -> Path:
    """The run directory of the policy vical ships for the workspace named ``workspace``."""
    if workspace not in SHIPPED_POLICIES:
        raise ConfigError(
            f"vical ships no learned policy for workspace {workspace!r} (only for {sorted(SHIPPED_POLICIES)}); "
            f"{TRAIN_HINT} workspace={workspace}"
        )
    return SHIPPED_POLICIES[workspace]


def learned_policy(
    run_dir: str | None = None,
    workspace: str = DEFAULT_WORKSPACE,
    name: str = "model-free learned policy",
    max_steps: int | None = None,
) -> LearnedPolicy:
    """The factory ``conf/policy/learned.yaml`` names: the agent of ``run_dir`` (``policy.run_dir=<run>``),
    or, when ``run_dir`` is None, the policy shipped for the workspace named ``workspace``."""
    return LearnedPolicy.from_run(run_dir or shipped_policy_dir(workspace), name=name, max_steps=max_steps)


def person_policy(
    run_dir: str | None = None, name: str = "learned policy (person)", max_steps: int | None = None
) -> LearnedPolicy:
    """The factory ``conf/policy/learned_person.yaml`` names: the agent of ``run_dir``, or, when it is None, the
    policy vical ships for a person who holds the sensor (trained with vical-guide's simulated person)."""
    return LearnedPolicy.from_run(run_dir or PERSON_POLICY_DIR, name=name, max_steps=max_steps)

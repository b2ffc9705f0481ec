"""The real configs of conf/, composed with Hydra as the apps compose them (for tests that build envs)."""

from pathlib import Path

from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

CONF = Path(__file__).resolve().parents[1] / "conf"


def composed(config_name: str = "evaluate", overrides: tuple[str, ...] | list[str] = ()) -> dict:
    """``conf/<config_name>.yaml`` with ``overrides``: the ``env`` node and its groups, resolved to plain containers."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name=config_name, overrides=list(overrides))
    return {
        key: OmegaConf.to_container(cfg[key], resolve=True) for key in ("env", "sim", "sensor", "task", "workspace")
    }


def env_config(task: str = "intrinsic", workspace: str = "practitioner", *overrides: str) -> dict:
    """The calibration env's config (``_target_``, ``sim``, ``sensor``, ``task`` and the MDP) for ``task``."""
    return composed("evaluate", [f"task={task}", f"workspace={workspace}", *overrides])["env"]


def env_parts(
    task: str = "intrinsic", workspace: str = "practitioner", *overrides: str
) -> tuple[dict, dict, dict, dict]:
    """``(sim, sensor, task, mdp)``: the arguments of ``CalibrationEnv`` for ``task`` in ``workspace``."""
    env = env_config(task, workspace, *overrides)
    mdp = {k: v for k, v in env.items() if k not in ("_target_", "sim", "sensor", "task")}
    return env["sim"], env["sensor"], env["task"], mdp


def resolved_policy(name: str, *overrides: str) -> dict:
    """``conf/policy/<name>.yaml`` chosen as vical-evaluate's ``policy`` with ``overrides``, resolved."""
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=[f"policy={name}", *overrides])
    return OmegaConf.to_container(cfg.policy, resolve=True)

"""vical-train: every config composes and validates; a killed run resumed from its directory ends exactly as an
uninterrupted run (SIGKILL of a real subprocess mid-run)."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import pytest
import torch
from hydra import compose, initialize_config_dir

from vical.rl.checkpoint import load_checkpoint
from vical.rl.trainer import AGENT, CHECKPOINT, make_env, parse_settings, train

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"
TINY = [
    "agent.hidden_sizes=[16,16]",
    "agent.batch_size=32",
    "+env.max_episode_steps=50",
    "torch_threads=1",
    "train.total_steps=600",
    "train.warmup_steps=100",
    "train.checkpoint_every=100",
    "train.eval_every=300",
    "train.eval_episodes=1",
    "train.plot_every_episodes=10",
    "train.progress=false",
]


def composed(overrides: list[str]):
    with initialize_config_dir(str(CONF), version_base="1.3"):
        return compose("train", overrides=overrides)


@pytest.mark.parametrize("agent", ["sac", "sac_authors"])
def test_every_agent_config_composes_validates_and_builds_its_env(tmp_path, agent):
    cfg = composed([f"agent={agent}", f"run_dir={tmp_path}"])
    settings = parse_settings(cfg)
    assert isinstance(make_env(settings.env).unwrapped, gym.Env)
    assert settings.agent.hidden_sizes == [256, 256] and settings.torch_threads == 2
    if agent == "sac_authors":  # the calibration paper's authors' settings
        a = settings.agent
        assert (a.gamma, a.tau, a.lr, a.batch_size, a.n_q, a.alpha) == (0.9, 0.01, 3e-4, 128, 1, 1.0)


def run_app(*args: str, cwd: Path) -> subprocess.Popen:
    """``vical-train`` in a subprocess started outside the repository (the app must find its config anyway)."""
    return subprocess.Popen(
        [str(Path(sys.executable).parent / "vical-train"), *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def kill_after_first_checkpoint(proc: subprocess.Popen, checkpoint: Path, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not checkpoint.exists():
        assert proc.poll() is None, f"vical-train exited before its first checkpoint:\n{proc.stdout.read()}"
        assert time.monotonic() < deadline, "no checkpoint appeared"
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()


def test_killed_run_resumes_to_the_same_parameters_as_an_uninterrupted_run(tmp_path):
    run = tmp_path / "run"
    proc = run_app(*TINY, f"hydra.run.dir={run}", cwd=tmp_path)
    kill_after_first_checkpoint(proc, run / CHECKPOINT)
    assert proc.returncode == -signal.SIGKILL
    killed_at = load_checkpoint(run / CHECKPOINT)["counters"]["step"]
    assert 100 <= killed_at < 600 and not (run / AGENT).exists()

    # a resume that changes a setting which alters the numbers is refused, naming it
    refused = run_app(f"resume={run}", "agent.gamma=0.5", cwd=tmp_path)
    out = refused.communicate(timeout=120)[0]
    assert refused.returncode != 0 and "agent.gamma: 0.99 (checkpoint) vs 0.5 (now)" in out

    resumed = run_app(f"resume={run}", cwd=tmp_path)
    out = resumed.communicate(timeout=300)[0]
    assert resumed.returncode == 0, out
    assert f"from step {killed_at}" in out and "trained 600 steps" in out

    full = train(composed([*TINY, f"run_dir={tmp_path / 'full'}"]))
    final = torch.load(run / AGENT, weights_only=True)["model"]
    expected = full.agent.state_dict()
    assert final.keys() == expected.keys()
    for key, value in expected.items():
        assert torch.equal(final[key], value), key
